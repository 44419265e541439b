"""The plain passes on several threads (accelnav.estimate.chunked, ``ACCELNAV_THREADS``) write the very bytes
of the passes run axis after axis: 1, 2 and 3 axes, chunk edges inside a clipped stretch, NaN, an invalid
first and last sample, the filter alone, the smoother alone and both, compact and full output, and a model
whose steady rows settle inside the run."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import edited_model

from accelnav import resources
from accelnav.errors import UserError
from accelnav.estimate import chunked
from accelnav.estimate import fastsmooth as fs
from accelnav.model.design import axis_design
from accelnav.model.edit import with_axis_bias, with_noise
from accelnav.model.load import load_model

Z_AXIS = '\n[[axes]]\nname = "z"\nc1 = 0.03\nc2 = -0.07\nT = 200.0\n'


def _models():
    base = load_model()
    one = edited_model([('[[axes]]\nname = "y"\nc1 = -0.05\nc2 = 0.12\nT = 240.0\nzero_g_v = 2.501\n', "")])
    three = edited_model([("zero_g_v = 2.501\n", "zero_g_v = 2.501\n" + Z_AXIS)])
    fast = base
    for ax in base.axes:  # a bias time constant of 0.5 s: the steady rows settle within ~1 200 samples
        fast = with_axis_bias(fast, ax.name, ax.c1, ax.c2, 0.5)
    return {"one": one, "two": base, "three": three, "settles": with_noise(fast, sigma_eps=0.05)}


MODELS = _models()


def _record(model, n, seed=11):
    rng = np.random.default_rng(seed)
    k = len(model.axes)
    t = np.arange(n) / model.rate_hz
    accel = np.cumsum(rng.normal(0, 0.05, (n, k)), axis=0) + rng.normal(0, 0.02, (n, k))
    clipped = np.zeros((n, k), dtype=bool)
    clipped[n // 3 : n // 3 + 13, 0] = True  # across the edge of a 97-sample chunk
    clipped[0, k - 1] = clipped[n - 1, k - 1] = True  # both ends invalid on the last axis
    accel[n // 2, 0] = np.nan
    if k > 2:
        accel[n // 4 : n // 4 + 5, 1] = np.nan  # a gap on a middle axis
    return t, accel, clipped


def _members(path):
    with np.load(path) as f:
        return {k: (f[k].dtype, f[k].shape, f[k].tobytes()) for k in f.files}


def _run(monkeypatch, tmp_path, model, n, lanes, name, **kw):
    monkeypatch.setattr(chunked, "threads", lambda: lanes)
    monkeypatch.setattr(chunked, "THREADS_FROM", 0)
    out = tmp_path / f"{name}-{lanes}.npz"
    t, accel, clipped = _record(model, n)
    chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), out, **kw)
    return _members(out)


pytestmark = pytest.mark.usefixtures("own_steady_cache")


@pytest.mark.parametrize("model", list(MODELS))
@pytest.mark.parametrize(
    "stages, full, chunk",
    [(("smooth",), False, 97), (("filt", "smooth"), True, 97), (("filt",), False, 97), (("smooth",), False, None)],
)
def test_axes_on_threads_write_the_bytes_of_axes_in_order(tmp_path, monkeypatch, model, stages, full, chunk):
    m = MODELS[model]
    n = 4000
    if model == "settles":  # the design's settled rows, as a run longer than its transient reads them
        for j in range(len(m.axes)):
            assert len(fs.steady_gains(axis_design(m, j)).rows) < n // 2
    kw = dict(stages=stages, full=full, chunk=chunk, store_memory=1 << 30)
    seq = _run(monkeypatch, tmp_path, m, n, 1, model, **kw)
    pools = []

    class Pool(chunked.ThreadPoolExecutor):  # the threaded run did go on threads (not axes in order twice)
        def submit(self, *a, **k):
            pools.append(self)
            return super().submit(*a, **k)

    monkeypatch.setattr(chunked, "ThreadPoolExecutor", Pool)
    par = _run(monkeypatch, tmp_path, m, n, 2, model, **kw)
    assert bool(pools) == (len(m.axes) > 1)
    assert seq.keys() == par.keys()
    for key in seq:
        assert par[key] == seq[key], f"{key}: threaded output differs from axes in order"


def test_the_store_on_disk_with_threads_writes_the_same_bytes(tmp_path, monkeypatch):
    m = MODELS["three"]
    kw = dict(stages=("smooth",), full=False, chunk=211, store_memory=0)
    par = _run(monkeypatch, tmp_path, m, 3000, 2, "disk", **kw)
    assert par == _run(monkeypatch, tmp_path, m, 3000, 1, "disk", **kw)


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_a_bad_thread_count_is_refused_in_one_line(monkeypatch, tmp_path, value):
    monkeypatch.setenv(resources.THREADS_ENV, value)
    with pytest.raises(UserError, match=resources.THREADS_ENV):
        resources.threads()
    m = MODELS["two"]  # a run too short for threads refuses it too, before it writes anything
    t, accel, clipped = _record(m, 500)
    with pytest.raises(UserError, match=resources.THREADS_ENV):
        chunked.smooth_bounded(m, 500, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz")
    assert list(tmp_path.iterdir()) == []


def test_the_thread_count_is_bounded_by_the_cpus(monkeypatch):
    monkeypatch.setattr(resources.os, "cpu_count", lambda: 2)
    monkeypatch.setenv(resources.THREADS_ENV, "64")
    assert resources.threads() == 2
    monkeypatch.setenv(resources.THREADS_ENV, "1")
    assert resources.threads() == 1
    monkeypatch.delenv(resources.THREADS_ENV)
    assert resources.threads() == 1  # one unless asked


def test_the_allocator_is_tuned_only_where_it_applies():
    """glibc: the command asks it to reuse freed blocks (True); the user's own MALLOC_* settings stand. Asked in a
    process of its own: the settings hold for the process's life, and this one runs every other test."""
    import ctypes
    import os
    import subprocess
    import sys

    try:
        glibc = hasattr(ctypes.CDLL(None), "gnu_get_libc_version")
    except OSError:
        glibc = False
    code = "from accelnav.resources import reuse_freed_memory as k; print(k())"
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    for extra, want in (({}, glibc and sys.platform.startswith("linux")), ({"MALLOC_TRIM_THRESHOLD_": "1"}, False)):
        done = subprocess.run([sys.executable, "-c", code], env={**env, **extra}, capture_output=True, text=True,
                              timeout=60)  # fmt: skip
        assert done.stdout.strip() == str(want), done.stderr


def test_an_axis_failing_on_its_thread_raises_after_the_others_are_done(tmp_path, monkeypatch):
    """The error goes up only once every axis's thread has returned (none writes while the output is dropped);
    nothing is left behind."""
    import time

    m = MODELS["two"]
    real, finished = chunked._backward, []

    def backward(run, ax, s, e):
        if ax.j == 0:
            raise UserError("axis 0 fails")
        time.sleep(0.05)
        real(run, ax, s, e)
        finished.append(s)

    monkeypatch.setattr(chunked, "_backward", backward)
    monkeypatch.setattr(chunked, "threads", lambda: 2)
    monkeypatch.setattr(chunked, "THREADS_FROM", 0)
    t, accel, clipped = _record(m, 1000)
    out = tmp_path / "o" / "o.npz"
    out.parent.mkdir()
    with pytest.raises(UserError, match="axis 0 fails"):
        chunked.smooth_bounded(m, 1000, chunked.array_reader(t, accel, clipped), out, chunk=300, store_memory=1 << 30)
    assert finished == [900], "axis 1 had finished its chunk before the error went up"
    assert list(out.parent.iterdir()) == []
