"""Cycles per sample, flash and RAM of the generated filters on an 8-bit AVR (ATmega328P, 16 MHz,
32 KB flash, 2 KB RAM) in simavr, beside the host's bits.

For each shipped model (its covariance form): the comparison driver of
accelnav.hil_sim.targets.simavr (200 samples from init, 200 from a checkpoint 100 000 samples into a
run at rest), run in simavr; Timer1 at the CPU clock counts each sample's filter calls (all axes,
input conversion included, the UART output excluded). Baseline in the same run: the same C with
__builtin_clz on the 32-bit divisor (the generator before issue 26), which also builds without a
warning but does not give the host's bits. The gain-schedule form's filter alone is sized too: its
rows are in flash (PROGMEM), and it needs more flash than the part has.

Then the whole firmware (BOARD=atmega328p) in simavr, fed a 2 s shock run of stimulus frames over
its UART at 250000 baud: CPU cycles per sample for everything (UART bytes in, frame parsing, both
filters, compact telemetry out, the loop's idle polling), static RAM and the deepest stack; beside it
(baseline, same run) the filter calls alone from the first table.

    .venv/bin/python bench/speed/bench_avr.py

Issue 26's note (before the fix, with __builtin_clzl typed in by hand): about 30.8 k cycles per
2-axis sample, 26 KB of the 32 KB flash for two axes; gain schedule 45.9 KB. Issue 34's (before the AVR
routines of codegen/csrc/acn_runtime.h): about 30.1 k cycles per 2-axis sample of the filters, the
whole board 46 045 cycles per sample (default model); after, 18.6 k and 34.6 k. bench_arch.py prints
the before -> after per architecture from one run.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from accelnav.codegen.emit_c import emit
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import simavr
from accelnav.model.load import load_model
from accelnav.resources import models_dir

SAMPLES, WARM = 200, 100_000


def _stimulus(model):
    run = simulate(model, "stress", SAMPLES / model.rate_hz, 3)
    duty = model.sensor.kind == "duty_cycle"
    return (np.stack([run.t1, run.t2], axis=-1) if duty else run.code), duty


def main() -> int:
    try:
        simavr.require_avr()
    except simavr.AvrError as e:
        print(e)
        return 1
    mhz = simavr.F_CPU / 1e6
    print(f"{simavr.MCU} at {mhz:g} MHz in simavr. Cycles per sample: all axes' filter calls, mean / largest.\n")
    print("| model | form | clz | cycles from init | cycles late | CPU at rate | flash B | RAM B | image B | bits |")
    print("|---|---|---|---:|---:|---:|---:|---:|---:|---|")
    with tempfile.TemporaryDirectory() as tmp:
        wd = Path(tmp)
        for name in ("adxl250_default", "adxl202_duty"):
            model = load_model(models_dir() / f"{name}.toml")
            stim, duty = _stimulus(model)
            files = {k: v for k, v in emit(model, form="covariance").items() if k.endswith((".c", ".h"))}
            h = files["accelnav.h"]
            warm = simavr.run_host(files, simavr.driver_c("accelnav.h", h, stim, duty=duty, warm_steps=WARM), wd / "w")
            drv = simavr.driver_c("accelnav.h", h, stim, duty=duty, warm=[bytes.fromhex(r[1:]) for r in warm.records])
            host = simavr.run_host(files, drv, wd / "host")
            old = dict(files, **{"accelnav.c": files["accelnav.c"].replace("acn_clz32(d);", "__builtin_clz(d);")})
            for label, fs in (("acn_clz32", files), ("__builtin_clz (baseline)", old)):
                avr = simavr.run_avr(fs, drv, wd / label.split()[0])
                flash, ram = simavr.object_size(fs, wd / (label.split()[0] + "_obj"))
                cols = " | ".join(f"{t / n:.0f} / {m}" for t, m, n in avr.phases)
                cpu = max(m for _, m, _ in avr.phases) * model.rate_hz / simavr.F_CPU
                same = "= host" if avr.records == host.records else "differ"
                print(
                    f"| {name} | covariance | {label} | {cols} | {cpu:.1%} | {flash} | {ram} | {avr.flash} | {same} |"
                )
            gs = {k: v for k, v in emit(model, form="gain_schedule").items() if k.endswith((".c", ".h"))}
            flash, ram = simavr.object_size(gs, wd / "gs_obj")
            print(f"| {name} | gain_schedule | acn_clz32 | - | - | - | {flash} | {ram} | does not fit | - |")
    print(
        f"\nflash, RAM: the generated filter alone (avr-size of its object; its constant tables are in flash, so"
        f" RAM is 0: the state lives with the caller). image: the driver's whole ELF ({SAMPLES}-sample stimulus"
        f" table in flash, UART output). CPU at"
        f" rate: the largest sample's cycles at the model's rate. The part: {simavr.FLASH_BYTES} B flash,"
        f" {simavr.RAM_BYTES} B RAM."
    )
    _board()
    return 0


def _board() -> None:
    """The firmware board in simavr: cycles per sample of the whole loop, RAM and stack."""
    import subprocess

    from accelnav.hil_sim.targets import hil
    from accelnav.hil_sim.targets.firmware import make_firmware, manifest

    print(
        "\nBOARD=atmega328p (the whole firmware, stimulus over the UART), 2 s of shock (vehicle for the duty"
        " cycle), covariance form:\n"
    )
    print(
        "| model | samples | cycles per sample, whole loop | the filters alone (baseline) | flash B | RAM B | stack B |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name in ("adxl250_default", "adxl202_duty"):
        model = load_model(models_dir() / f"{name}.toml")
        if model.filter.form != "covariance":
            continue  # the gain schedule does not fit the part
        run = simulate(model, "shock" if model.sensor.kind == "analog" else "vehicle", 2.0, seed=9)
        stim = hil.stimulus(manifest(model.source), run)
        out = make_firmware("atmega328p", model.source)
        res = simavr.run_feed(out / "accelnav_fw.elf", stim, timeout=300)
        same = "= SIL" if res.telemetry == hil.run_sil(model, stim) else "DIFFERS from SIL"
        size = subprocess.run(["avr-size", "-A", str(out / "accelnav_fw.elf")], capture_output=True, text=True).stdout
        sec = {a: int(b) for a, b in (ln.split()[:2] for ln in size.splitlines() if ln.startswith("."))}
        files = {k: v for k, v in emit(model, form="covariance").items() if k.endswith((".c", ".h"))}
        stim_codes, duty = _stimulus(model)
        with tempfile.TemporaryDirectory() as tmp:
            avr = simavr.run_avr(files, simavr.driver_c("accelnav.h", files["accelnav.h"], stim_codes, duty=duty),
                                 Path(tmp))  # fmt: skip
        filt = avr.phases[0][0] / avr.phases[0][2]
        print(f"| {name} ({same}) | {len(run.t)} | {res.cycles / len(run.t):.0f} | {filt:.0f} | "
              f"{sec['.text'] + sec['.data']} | {sec['.data'] + sec['.bss']} | {res.stack} |")  # fmt: skip
    print("\ncycles per sample, whole loop: simavr's cycles from reset to the end of the run over the samples; the")
    print("loop waits for the UART's bytes (250000 baud) too, so this bounds the rate from above, not the CPU load.")


if __name__ == "__main__":
    sys.exit(main())
