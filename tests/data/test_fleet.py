"""Many recordings in one command (accelnav smooth --out-dir --jobs) and through Dask: each gives what a run of
its own gives; a broken one is reported in one line and the others finish.

Dask is the fleet extra (and in the test extra, which make setup installs); without it the Dask test skips,
unless ACCELNAV_REQUIRE_DASK=1 (set by .ci/run), where a missing Dask is a failure.
"""

from __future__ import annotations

import json
import logging
import os
import platform
import re
import subprocess
import sys
import threading

import numpy as np
import pytest
from conftest import REPO
from support.cachekey import private_cache
from support.cli import run_cli

from accelnav.data import smoothing
from accelnav.data.runfile import load_run
from accelnav.data.smoothing import smooth_batch, smooth_files, smooth_one, start_method
from accelnav.estimate import fastsmooth as fs
from accelnav.model.load import load_model


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Three NPZ recordings of different lengths and a file that is not one."""
    folder = tmp_path_factory.mktemp("fleet")
    model = load_model()
    rng = np.random.default_rng(8)
    paths = []
    for i, n in enumerate((500, 1200, 800)):
        path = folder / f"rec{i}.npz"
        accel = np.cumsum(rng.normal(0, 0.05, (n, len(model.axes))), axis=0)
        np.savez(path, t=np.arange(n) / model.rate_hz, accel=accel)
        paths.append(path)
    bad = folder / "broken.csv"
    bad.write_text("t_s,acc_x_m_s2\n0.0,abc\n")
    return paths, bad


def _same_as_alone(out, path, tmp_path, capsys):
    fs.clear_steady_cache()  # alone: its gains computed for it, not the rows a longer input of the fleet left
    fs.clear_gain_cache()
    status, _, err = run_cli(["smooth", path, "--out", tmp_path / "alone.npz"], capsys)
    assert status == 0, err
    got, ref = load_run(out)[0], load_run(tmp_path / "alone.npz")[0]
    for key in ("t", "smooth_x", "smooth_sd"):
        np.testing.assert_array_equal(got[key], ref[key], err_msg=key)


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_fleet_smooths_each_input_and_reports_the_one_that_fails(fleet, tmp_path, capsys, jobs, monkeypatch):
    private_cache(tmp_path, monkeypatch)  # no settled rows on disk: each process computes the rows it keeps
    paths, bad = fleet
    argv = ["smooth", paths[0], bad, *paths[1:], "--out-dir", tmp_path / "out", "--jobs", str(jobs)]
    status, out, err = run_cli(argv, capsys)
    assert status == 1 and "Traceback" not in err, err
    lines = out.strip().splitlines()
    assert sum(line.startswith("ok ") for line in lines) == 3
    (failed,) = [line for line in lines if line.startswith("FAILED")]
    assert str(bad) in failed and "line 2" in failed
    assert lines[-1].startswith("3 of 4 inputs smoothed") and "1 failed" in lines[-1]
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["rec0.npz", "rec1.npz", "rec2.npz"]
    for p in paths:  # rec2 after rec1 in one process: the kept rows of the longer run (fastsmooth.steady_gains)
        _same_as_alone(tmp_path / "out" / p.name, p, tmp_path, capsys)


def test_a_fleet_refuses_what_belongs_to_one_input_and_outputs_that_collide(fleet, tmp_path, capsys):
    paths, _ = fleet
    for extra in (["--fixes", paths[0]], ["--csv", tmp_path / "x.csv"], ["--out", tmp_path / "o.npz"]):
        status, _, err = run_cli(["smooth", *paths, "--out-dir", tmp_path / "o", *extra], capsys)
        assert status == 2 and len(err.strip().splitlines()) == 1 and extra[0] in err, err
    twin = tmp_path / "d" / "rec0.npz"
    twin.parent.mkdir()
    twin.write_bytes(paths[0].read_bytes())
    status, _, err = run_cli(["smooth", paths[0], twin, "--out-dir", tmp_path / "o"], capsys)
    assert status == 2 and "would both write" in err
    assert not (tmp_path / "o").exists()


def _need_dask() -> None:
    """The test skips without Dask, unless ACCELNAV_REQUIRE_DASK=1."""
    try:
        import dask.bag  # noqa: F401
    except ImportError:
        if os.environ.get("ACCELNAV_REQUIRE_DASK") == "1":
            pytest.fail("ACCELNAV_REQUIRE_DASK=1 but dask is not installed (pip install 'accelnav[fleet]')")
        pytest.skip("dask is not installed (the fleet extra: pip install 'accelnav[fleet]')")


def _dask_bag(pairs):
    """A Dask bag of two partitions over ``pairs`` (the test skips without Dask)."""
    _need_dask()
    import dask.bag as db

    return db.from_sequence(pairs, npartitions=2)


def test_the_library_under_dask(fleet, tmp_path, capsys):
    """The same task (smooth_one) mapped by a Dask bag over processes: the results of the command."""
    paths, bad = fleet
    outs = [tmp_path / f"{p.name.split('.')[0]}.npz" for p in (*paths, bad)]
    bag = _dask_bag(list(zip([*paths, bad], outs, strict=True)))
    results = bag.map(lambda po: smooth_one(po[0], po[1], {})).compute(scheduler="processes", num_workers=2)
    assert [r.ok for r in results] == [True, True, True, False]
    assert "line 2" in results[-1].message
    _same_as_alone(outs[1], paths[1], tmp_path, capsys)


def test_a_partition_under_dask_and_the_process_set_up_for_it(fleet, tmp_path, capsys):
    """smooth_batch over a Dask bag's partitions (the documented batch task): each partition's files in turn in
    one worker, the results of smooth_one in the inputs' order, the broken file reported; and glibc takes the
    settings of accelnav.resources.reuse_freed_memory in a fresh process (True; False where the C library has
    no mallopt or refuses them)."""
    paths, bad = fleet
    outs = [tmp_path / f"{p.name.split('.')[0]}.npz" for p in (*paths, bad)]
    bag = _dask_bag(list(zip([*paths, bad], outs, strict=True)))
    results = bag.map_partitions(smooth_batch, {}).compute(scheduler="processes", num_workers=2)
    assert [r.path for r in results] == [str(p) for p in (*paths, bad)]
    assert [r.ok for r in results] == [True, True, True, False] and "line 2" in results[-1].message
    _same_as_alone(outs[2], paths[2], tmp_path, capsys)
    if sys.platform == "linux" and platform.libc_ver()[0] == "glibc":
        code = "from accelnav.resources import reuse_freed_memory as k; print(k())"
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
        assert done.stdout.strip() == "True", done.stderr


def _documented_block() -> str:
    """docs/python.rst's Dask block, as printed there."""
    blocks = re.findall(r"\.\. code-block:: python\n\n((?:   .*\n|\n)+)", (REPO / "docs" / "python.rst").read_text())
    (block,) = [b for b in blocks if "map_partitions(smooth_batch" in b]
    return "\n".join(line[3:] for line in block.splitlines())


# run in a fresh interpreter (one thread: start_method() forks, as for a user's script): the block as printed,
# then again without its chunksize=1; Dask's pretask/posttask callbacks count the tasks handed to the processes
# and not yet back
_PROBE = """
import json
from dask.callbacks import Callback

flight = {{"now": 0, "most": 0}}
def _pre(key, dsk, state):
    flight["now"] += 1
    flight["most"] = max(flight["most"], flight["now"])
def _post(key, result, dsk, state, worker_id):
    flight["now"] -= 1
Callback(pretask=_pre, posttask=_post).register()
paths, options, workers = {paths!r}, {{}}, 2
seen = {{}}
for out_dir, block in (({out!r}, {block!r}), ({out2!r}, {batched!r})):
    flight["most"] = 0
    exec(block)
    seen[out_dir] = {{"most": flight["most"], "ok": [r.ok for r in results], "failed": [r.message for r in failed],
                      "pids": sorted({{r.pid for r in results}})}}
print(json.dumps(seen))
"""


def test_the_documented_dask_block_hands_a_partition_to_a_free_process(fleet, tmp_path, capsys):
    """docs/python.rst's Dask recipe (what bench_smooth_e2e's fleet row runs) smooths each input as a run of its
    own, reports the broken one, and never hands a process more partitions than it can start: at most one per
    process in flight. Without its chunksize=1 Dask hands the ready partitions out six at a time, decided before
    any runs (all four here went to one process in one batch): the count says so."""
    _need_dask()
    paths, bad = fleet
    block = _documented_block()
    assert "chunksize=1" in block and "start_method()" in block, block
    batched = block.replace(", chunksize=1", "")
    assert batched != block
    out, out2 = tmp_path / "out", tmp_path / "batched"
    code = _PROBE.format(paths=[str(p) for p in (*paths, bad)], out=str(out), out2=str(out2), block=block,
                         batched=batched)  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    seen = json.loads(done.stdout.strip().splitlines()[-1])
    recipe, without = seen[str(out)], seen[str(out2)]
    assert recipe["ok"] == [True, True, True, False] and len(recipe["failed"]) == 1, recipe
    assert "line 2" in recipe["failed"][0]
    assert 1 <= recipe["most"] <= 2, recipe  # a partition each, handed out as a process frees
    # the probe sees the batching the setting prevents: all four in one batch, to one process
    assert without["most"] == 4 and len(without["pids"]) == 1, (
        f"Dask no longer batches, the probe cannot tell: {without}"
    )
    for p in paths:
        _same_as_alone(out / p.name, p, tmp_path, capsys)


def test_a_batch_says_once_that_the_environment_keeps_glibc_as_it_is(monkeypatch, caplog):
    """dask.distributed's workers start with MALLOC_TRIM_THRESHOLD_ set: accelnav leaves glibc as the environment
    says, and the worker says so once (not once per partition), naming the variable and what it costs. (The
    variable set, reuse_freed_memory changes nothing in this process.)"""
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    monkeypatch.setattr(smoothing, "_said_malloc", False)
    with caplog.at_level(logging.WARNING, logger="accelnav"):
        assert smooth_batch([], {}) == [] and smooth_batch([], {}) == []
    said = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(said) == 1 and "MALLOC_TRIM_THRESHOLD_ set" in said[0] and "twice the CPU" in said[0], said


def test_workers_are_forked_only_where_no_other_thread_could_hold_a_lock(fleet, tmp_path, capsys):
    """A process of one thread (the command's) forks its workers on Linux, ready at once; with another thread
    running (a notebook's, a server's) they are spawned, and the fleet gives the same files."""
    code = "from accelnav.data.smoothing import start_method as s; print(s())"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == ("fork" if sys.platform == "linux" else "spawn"), done.stderr
    paths, _ = fleet
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert start_method() == "spawn"
        results = smooth_files(paths[:2], tmp_path / "out", jobs=2)
    finally:
        stop.set()
        other.join()
    assert [r.ok for r in results] == [True, True]
    _same_as_alone(tmp_path / "out" / paths[0].name, paths[0], tmp_path, capsys)


def test_an_output_named_like_its_input_is_refused_and_the_input_kept(fleet, capsys):
    """--out-dir being the inputs' own folder would make each output the file it reads (a.npz -> a.npz): each is
    refused by the output rule in one line, and the recordings stay as they were."""
    paths, _ = fleet
    before = [p.read_bytes() for p in paths]
    status, out, err = run_cli(["smooth", *paths, "--out-dir", paths[0].parent], capsys)
    assert status == 1
    for p in paths:
        assert f"{p.name}: --out: {p} is the input {p} (the same file); give another name" in out + err
    assert [p.read_bytes() for p in paths] == before
