"""Codegen cost does not grow with the declared run: a 1 kHz 3-axis model and a 10 kHz one generate
(C and --report) within 300 MB, measured with tracemalloc and the child's peak RSS; a rate x run-length
product beyond what the generator accepts is refused in one line before anything is allocated.

Time is not asserted here (bench/speed/bench_codegen_cost.py measures it beside the previous generator)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from accelnav.codegen.ranges import MAX_RUN_SAMPLES, RangeError
from accelnav.model.load import load_model, loads_model

LIMIT_MB = 300.0

_CHILD = r"""
import json, resource, sys, tracemalloc
def peak_rss():
    # VmHWM: this process image's high-water mark (ru_maxrss would carry the forked parent's over exec)
    try:
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
from accelnav.model.load import loads_model
from accelnav.codegen.emit_c import emit
from accelnav.codegen.report import report
model = loads_model(sys.stdin.read(), source="cost.toml")
tracemalloc.start()
files = emit(model)
text = report(model, form=None, arith="fixed", files=files, prefix="accelnav")
peak = tracemalloc.get_traced_memory()[1]
rss = peak_rss()
print(json.dumps({"traced": peak, "rss": rss, "axes": text.count("\naxis "), "c": len(files["accelnav.c"])}))
"""

Z_AXIS = '[[axes]]\nname = "z"\nc1 = 0.03\nc2 = -0.02\nT = 200.0\n\n[noise]'


def model_text(rate: float, run_s: float, three_axes: bool = False) -> str:
    text = load_model().text.replace("rate_hz = 100.0", f"rate_hz = {rate:.1f}")
    text = text.replace("max_run_s = 3600.0", f"max_run_s = {float(run_s)!r}")
    return text.replace("[noise]", Z_AXIS, 1) if three_axes else text


@pytest.mark.parametrize(
    "rate,run_s,three",
    [(1000.0, 3600.0, True), (10000.0, MAX_RUN_SAMPLES / 10000.0 - 1.0, False)],
    ids=["1kHz-3axes-1h", "10kHz-longest-accepted"],
)
def test_codegen_memory_independent_of_run_length(rate, run_s, three):
    text = model_text(rate, run_s, three)
    out = subprocess.run([sys.executable, "-c", _CHILD], input=text, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["axes"] == (3 if three else 2)
    assert got["traced"] / 1e6 <= LIMIT_MB, f"tracemalloc peak {got['traced'] / 1e6:.0f} MB"
    assert got["rss"] / 1e6 <= LIMIT_MB, f"peak RSS {got['rss'] / 1e6:.0f} MB"


def test_too_long_a_run_is_refused_before_it_allocates(tmp_path, capsys):
    import tracemalloc

    from accelnav.cli import main
    from accelnav.codegen.emit_c import emit

    text = model_text(100000.0, 1800.0)  # accepted by the validator; 1.8e8 samples per axis
    model = loads_model(text, source="fast.toml")
    tracemalloc.start()
    try:
        with pytest.raises(RangeError, match=r"sampling\.rate_hz x ranges\.max_run_s: 100000 Hz x 1800 s") as e:
            emit(model)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 2e6, f"{peak / 1e6:.1f} MB allocated before the refusal"
    assert "accepted: at most" in str(e.value) and "\n" not in str(e.value)
    path = tmp_path / "fast.toml"
    path.write_text(text)
    assert main(["codegen", str(path), "--out", str(tmp_path / "gen")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "rate_hz x ranges.max_run_s" in err
    assert not (tmp_path / "gen").exists()
    # the limit itself is accepted, one sample more is not
    from accelnav.codegen.ranges import run_samples

    assert run_samples(loads_model(model_text(1000.0, MAX_RUN_SAMPLES / 1000.0), source="ok")) == MAX_RUN_SAMPLES
    with pytest.raises(RangeError):
        run_samples(loads_model(model_text(1000.0, (MAX_RUN_SAMPLES + 1) / 1000.0), source="over"))
