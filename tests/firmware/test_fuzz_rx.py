"""The libFuzzer harness of the firmware's receive path (firmware/fuzz/), run for a bounded time.

CI runs it for FUZZ_SECONDS from the seed corpus kept in the repo, with ASan and UBSan and the
harness's own check of every frame the firmware sends. Without clang (or its fuzzer runtime) the
test skips and says why; with ACCELNAV_REQUIRE_FUZZ=1 (set by .ci/run, which installs them) that
is a failure. A crash fails the test; the failing input is kept under the cache folder and its
bytes are printed in the failure so a CI log is enough to reproduce it.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest

from accelnav.resources import cache_root, firmware_dir

FUZZ_SECONDS = int(os.environ.get("ACCELNAV_FUZZ_SECONDS", "60"))


def _fuzz_module():
    path = firmware_dir() / "fuzz" / "fuzz.py"
    if not path.is_file():
        pytest.skip(f"{path} absent (an installed wheel carries no fuzz harness)")
    spec = importlib.util.spec_from_file_location("accelnav_fuzz_rx", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _unavailable(reason: str):
    if os.environ.get("ACCELNAV_REQUIRE_FUZZ") == "1":
        pytest.fail(f"ACCELNAV_REQUIRE_FUZZ=1 but {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def fuzz():
    return _fuzz_module()


def test_seed_corpus_matches_the_frame_layout(fuzz):
    """The committed seeds are what the generator's layout gives today (rerun `fuzz.py corpus` if not)."""
    kept = {p.name: p.read_bytes() for p in fuzz.SEEDS.iterdir()}
    assert kept == fuzz.seeds(), "firmware/fuzz/corpus is stale: python firmware/fuzz/fuzz.py corpus"
    assert sum(map(len, kept.values())) < 4096


def test_libfuzzer_receive_path(fuzz):
    out = cache_root() / "fuzz" / "rx"
    missing = fuzz.runtime_missing(out)
    if missing:
        _unavailable(missing)
    exe = fuzz.build(out)  # with the tools there, a harness that does not build is a failure
    fig = fuzz.run(exe, FUZZ_SECONDS, out, fresh=True)
    saved = "".join(f"\n  {p}: {Path(p).read_bytes().hex()}" for p in fig["artifacts"])
    assert fig["returncode"] == 0 and not fig["artifacts"], (
        f"libFuzzer found a failing input (reproduce: {exe} FILE):{saved}\n{fig['log_tail']}"
    )
    assert "done_cov" in fig and fig["number_of_executed_units"] > 0, f"no final stats:\n{fig['log_tail']}"
    print(
        f"\nlibFuzzer fuzz_rx, {FUZZ_SECONDS} s: {fig['number_of_executed_units']} execs, "
        f"{fig['average_exec_per_sec']} exec/s, cov {fig['done_cov']} ft {fig['done_ft']} "
        f"(seeds alone: cov {fig['inited_cov']} ft {fig['inited_ft']}), {fig['new_units_added']} new units"
    )
