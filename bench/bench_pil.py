"""Benchmark: emulated samples per second end to end (PIL), beside the same firmware in-process (SIL).

One simulated run per model (analog ADC codes and duty-cycle counts): the
stimulus goes into UART1 of qemu-system-arm (mps2-an385), UART0 is recorded
through accelnav.link.recorder into a log and decoded; the SIL run feeds the same
bytes to the host-board build through cffi. Both include framing and decode.
Usage: python bench/bench_pil.py [--seconds 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from baselines import best_of

from accelnav.codegen.model import load_model
from accelnav.codegen.resources import models_dir
from accelnav.hil_sim import hil
from accelnav.hil_sim.firmware import manifest
from accelnav.hil_sim.sensor import simulate
from accelnav.link.telemetry import decode_all


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per run")
    args = ap.parse_args()
    print("| model | input | samples | SIL samples/s | PIL samples/s (QEMU, end to end) | SIL/PIL | frames equal |")
    print("|---|---|---|---|---|---|---|")
    for name in ("adxl250_default", "adxl202_duty"):
        model = load_model(models_dir() / f"{name}.toml")
        run = simulate(model, "vehicle", args.seconds, seed=3)
        n = len(run.t)
        man = manifest(model.source)
        stim = hil.stimulus(man, run)
        hil.run_sil(model, stim)  # build once, outside the timing
        t_sil = best_of(lambda: decode_all(man, hil.run_sil(model, stim)), 3)  # noqa: B023
        sil = hil.run_sil(model, stim)
        hil.make_firmware("mps2_an385", model.source)  # build outside the timing too
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            pil = hil.run_pil(model, stim, n, Path(tmp) / "pil.acnlog")
            decode_all(man, pil.telemetry)
            t_pil = time.perf_counter() - t0
        same = pil.telemetry == sil
        print(
            f"| {name} | {model.sensor.kind} | {n} | {n / t_sil:,.0f} | {n / t_pil:,.0f} | "
            f"{t_pil / t_sil:,.0f} | {'yes' if same else 'NO'} |"
        )


if __name__ == "__main__":
    main()
