"""Target table: the gain schedule's C table per axis against issue #12's 2 KB (goal, measured, met).

A target, not a behaviour, so it lives here rather than in the test suite: the table's size is what the
planner gives today (codegen.ranges.plan_axis -> emit_c._schedule_for), rows of 24 B (dr, dv, de_lo,
de_hi, ka, end) plus the closing row. Above 100 Hz only axis 0 is planned (the axes share the time).
Issue #12 was declared blocked on this target (bench/studies/study_schedule_table.py: no piecewise table up to
cubic pieces meets it under the 1e-3 sigma accuracy), so 'met' reading 'no' is the known state.

Usage: python bench/speed/bench_schedule_table.py
"""

from __future__ import annotations

import re

from accelnav.codegen.emit_c import _schedule_for
from accelnav.codegen.ranges import plan_axis
from accelnav.model.load import load_model, loads_model
from accelnav.resources import models_dir

ROW_BYTES = 24
GOAL = 2048  # B per axis, issue #12
CASES = (
    ("adxl250_default.toml", 100.0),
    ("adxl250_default.toml", 1000.0),
    ("adxl250_default.toml", 10000.0),
    ("adxl202_duty.toml", 100.0),  # the duty-cycle part is accepted at 100 Hz only (its 5 ms capture period)
)


def schedule_model(name: str, rate: float):
    """The shipped model in the gain-schedule form at ``rate``, its run cut to what the generator accepts."""
    m = load_model(models_dir() / name)
    text = re.sub(r'^form = "\w+"', 'form = "gain_schedule"', m.text, flags=re.M)
    text = text.replace(f"rate_hz = {m.rate_hz!r}", f"rate_hz = {rate!r}")
    if rate * m.ranges.max_run_s > 2**23:
        text = re.sub(r"max_run_s = [0-9.]+", f"max_run_s = {2**23 // int(rate)}.0", text)
    return loads_model(text, source=f"{name}@{rate:g}Hz")


def main() -> None:
    print("| model | rate (Hz) | axis | goal (B) | measured (B) | met |")
    print("|---|---:|---|---:|---:|---|")
    for name, rate in CASES:
        model = schedule_model(name, rate)
        for i in range(len(model.axes)) if rate <= 100 else (0,):
            size = (_schedule_for(plan_axis(model, i, "gain_schedule")).n_segments + 1) * ROW_BYTES
            met = "yes" if size <= GOAL else "no"
            print(f"| {name} | {rate:g} | {model.axes[i].name} | {GOAL} | {size} | {met} |")


if __name__ == "__main__":
    main()
