"""libFuzzer on the CSV reader's C parser (host/data/csrc/csvnum.c), with ASan and UBSan, for a bounded time.

The harness (tests/support/fuzz_csvnum.c) gives the parser buffers of exactly the input's length and
checks every number it accepts against strtod's correctly rounded bits. Built with the firmware fuzz
harness's tools (clang and its fuzzer runtime, firmware/fuzz/fuzz.py); without them the test skips and
says why (a failure under ACCELNAV_REQUIRE_FUZZ=1). A failing input's bytes are printed.
"""

from __future__ import annotations

import os
import subprocess

from conftest import SUPPORT
from support.libfuzzer import fuzz_module, unavailable

from accelnav.data import csvnum
from accelnav.native.cbuild import STRICT_WARN
from accelnav.resources import cache_root

FUZZ_SECONDS = int(os.environ.get("ACCELNAV_FUZZ_SECONDS", "20"))
# (delimiter byte index, fields, wanted-field mask) then a piece: what the harness's first bytes say
SEEDS = {
    "plain": b"\x00\x03\x07t,1.5,2e3\n0.1,-0,  7 \n1e22,9007199254740993,.5",
    "decimal comma": b"\x01\x02\x03" + b"0,01188;-1,5e-3\n2;3",
    "tabs, a field not wanted": b"\x02\x03\x05" + b"1\tx y\t3\n4\t\xc3\xa9\t6",
    "long and tiny": b"\x00\x02\x03" + b"0." + b"0" * 330 + b"247032822920623272e-10,1e-400\n1e400,-0e99999",
    "refused": b"\x00\x02\x03" + b"inf,1\n,2\n1,2,\n\n",
}


def test_libfuzzer_csv_parser(tmp_path):
    fuzz = fuzz_module()
    out = cache_root() / "fuzz" / "csvnum"
    missing = fuzz.runtime_missing(out)
    if missing:
        unavailable(missing)
    exe = out / "fuzz_csvnum"
    fuzz._cc([fuzz.clang(), *STRICT_WARN, "-O1", "-g", *fuzz.SANITIZE, f"-I{csvnum.CSRC}",
              str(SUPPORT / "fuzz_csvnum.c"), str(csvnum.CSRC / "csvnum.c"), "-o", str(exe)])  # fmt: skip
    seeds, crashes = tmp_path / "seeds", tmp_path / "crashes"
    seeds.mkdir()
    crashes.mkdir()
    for i, data in enumerate(SEEDS.values()):
        (seeds / f"seed{i}").write_bytes(data)
    cmd = [str(exe), f"-max_total_time={FUZZ_SECONDS}", "-print_final_stats=1", "-timeout=10", "-max_len=4096",
           fuzz.rss_limit(), f"-artifact_prefix={crashes}/", str(seeds)]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=FUZZ_SECONDS + 300)
    fig = fuzz.parse(done.stderr)
    found = "".join(f"\n  {p.name}: {p.read_bytes().hex()}" for p in crashes.iterdir())
    assert done.returncode == 0 and not found, f"a failing input (reproduce: {exe} FILE):{found}\n{done.stderr[-4000:]}"
    assert fig.get("number_of_executed_units", 0) > 1000, f"libFuzzer barely ran:\n{done.stderr[-2000:]}"
    print(f"\nlibFuzzer csvnum, {FUZZ_SECONDS} s: {fig['number_of_executed_units']} execs, cov {fig.get('done_cov')}")
