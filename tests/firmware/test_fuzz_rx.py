"""The libFuzzer harness of the firmware's receive path (firmware/fuzz/), run for a bounded time.

CI runs it for FUZZ_SECONDS from the corpus kept in the repo (the seeds and grown/, which long runs
grow through `make fuzz-merge`), with ASan and UBSan and the harness's own check of every frame the
firmware sends; before that, every committed input (seeds, grown/, regressions/: what earlier runs
found) is replayed once. Without clang (or its fuzzer runtime) the
test skips and says why; with ACCELNAV_REQUIRE_FUZZ=1 (set by .ci/run, which installs them) that
is a failure. A crash fails the test; the failing input is kept under the cache folder and its
bytes are printed in the failure so a CI log is enough to reproduce it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from support.libfuzzer import fuzz_module, unavailable

from accelnav.resources import cache_root

FUZZ_SECONDS = int(os.environ.get("ACCELNAV_FUZZ_SECONDS", "60"))


@pytest.fixture(scope="module")
def fuzz():
    return fuzz_module()


def test_seed_corpus_matches_the_frame_layout(fuzz):
    """The committed seeds are what the generator's layout gives today (rerun `fuzz.py corpus` if not)."""
    kept = {p.name: p.read_bytes() for p in fuzz.SEEDS.iterdir()}
    assert kept == fuzz.seeds(), "firmware/fuzz/corpus is stale: python firmware/fuzz/fuzz.py corpus"
    assert sum(map(len, kept.values())) < 4096


def _harness(fuzz) -> tuple[Path, Path]:
    out = cache_root() / "fuzz" / "rx"
    missing = fuzz.runtime_missing(out)
    if missing:
        unavailable(missing)
    return fuzz.build(out), out  # with the tools there, a harness that does not build is a failure


def test_the_repository_corpus_stays_small(fuzz):
    grown = [p for p in fuzz.GROWN.iterdir()] if fuzz.GROWN.is_dir() else []
    assert sum(p.stat().st_size for p in grown) <= fuzz.GROWN_MAX_BYTES
    assert not set(p.name for p in grown) & set(p.name for p in fuzz.SEEDS.iterdir())


def test_every_committed_input_replays_clean(fuzz):
    """The seeds, grown/ and every finding kept in regressions/ (fixed since): each run once, none fails."""
    inputs = fuzz.committed_inputs()
    assert len(inputs) > len(list(fuzz.SEEDS.iterdir()))  # grown/ is there, not only the seeds
    exe, _ = _harness(fuzz)
    done = fuzz.replay(exe, inputs)
    assert done.returncode == 0, done.stderr[-4000:]
    ran = done.stderr.count("Running: ")
    assert ran == len(inputs), f"{ran} of {len(inputs)} inputs ran:\n{done.stderr[-2000:]}"


def test_a_finding_is_kept_as_a_regression_input_once(fuzz, tmp_path):
    art = tmp_path / "crashes"
    art.mkdir()
    (art / "crash-abc").write_bytes(b"\x01\x03\xff")
    (art / "timeout-def").write_bytes(b"\x00zz")
    reg = tmp_path / "regressions"
    kept = fuzz.keep_findings([str(art / "crash-abc"), str(art / "timeout-def")], reg)
    again = fuzz.keep_findings([str(art / "crash-abc")], reg)
    assert sorted(p.name.split("-")[0] for p in reg.iterdir()) == ["crash", "timeout"]
    assert kept[0] == again[0] and kept[0].read_bytes() == b"\x01\x03\xff"


def test_libfuzzer_receive_path(fuzz):
    exe, out = _harness(fuzz)
    fig = fuzz.run(exe, FUZZ_SECONDS, out, fresh=True)
    saved = "".join(f"\n  {p}: {Path(p).read_bytes().hex()}" for p in fig["artifacts"])
    assert fig["returncode"] == 0 and not fig["artifacts"], (
        f"libFuzzer found a failing input (reproduce: {exe} FILE):{saved}\n{fig['log_tail']}"
    )
    assert "done_cov" in fig and fig["number_of_executed_units"] > 0, f"no final stats:\n{fig['log_tail']}"
    print(
        f"\nlibFuzzer fuzz_rx, {FUZZ_SECONDS} s: {fig['number_of_executed_units']} execs, "
        f"{fig['average_exec_per_sec']} exec/s, cov {fig['done_cov']} ft {fig['done_ft']} "
        f"(repository corpus alone: cov {fig['inited_cov']} ft {fig['inited_ft']}), {fig['new_units_added']} new units"
    )


def test_a_large_parent_is_not_the_harness_memory(fuzz, tmp_path):
    """A harness started from a process holding more than its own memory limit (a long test run) fuzzes as from a
    small one: Linux hands the parent's peak RSS to the child, which libFuzzer reads as its own."""
    exe, _ = _harness(fuzz)
    held = np.ones((fuzz.RSS_MB + 256) << 17)  # RSS_MB + 256 MiB of float64, touched
    fig = fuzz.run(exe, 3, tmp_path / "run")
    assert held[-1] == 1.0
    assert fig["returncode"] == 0 and not fig["artifacts"], f"{fig['artifacts']}\n{fig['log_tail'][-2000:]}"
