"""Benchmark: emulated samples per second end to end (PIL), beside the same firmware in-process (SIL).

For each model (the two shipped ones at their 100 Hz, and the ADXL250 model at
1 kHz, written to a temporary folder) one simulated run: SIL feeds the stimulus
to the host-board build through cffi; PIL runs the same stimulus on an emulated
board the way `accelnav hil --target pil` does (the file feed over
semihosting, hil_sim.qemu.run_feed), and, as the same-run baseline, over the
board's UARTs recorded by accelnav.link.recorder (the path PIL took before).
Every time includes framing and decode; PIL includes QEMU's start and exit.
"real time" is samples/s over the model's rate: 10x at 100 Hz is 1 000
samples/s, 1x at 1 kHz is 1 000 samples/s.
Usage: python bench/run_all.py bench/speed/bench_pil.py [--seconds 20] [--no-uart]
           [--boards mps2_an385,microbit,stm32vldiscovery]
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path

from baselines import best_of

from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.targets import hil
from accelnav.hil_sim.targets.firmware import firmware_images, manifest
from accelnav.hil_sim.targets.qemu import MACHINES
from accelnav.link.decoder import decode_all
from accelnav.model.load import load_model
from accelnav.resources import models_dir


def models(tmp: Path) -> list[tuple[str, Path]]:
    """(label, model file): the shipped models, and the ADXL250 model at 1 kHz."""
    out = [(name, models_dir() / f"{name}.toml") for name in ("adxl250_default", "adxl202_duty")]
    text = (models_dir() / "adxl250_default.toml").read_text()
    fast, n = re.subn(r"^rate_hz = .*$", "rate_hz = 1000.0", text, flags=re.M)
    assert n == 1, "adxl250_default.toml: no rate_hz line"
    path = tmp / "adxl250_1khz.toml"
    path.write_text(fast)
    out.append(("adxl250_default at 1 kHz", path))
    return out


def pil_rate(model, stim: bytes, n: int, board: str, link: str, tmp: Path) -> tuple[float, bytes]:
    man = manifest(model.source)
    t0 = time.perf_counter()
    pil = hil.run_pil(model, stim, n, tmp / f"pil-{board}-{link}.acnlog", board=board, link=link)
    decode_all(man, pil.telemetry)
    return n / (time.perf_counter() - t0), pil.telemetry


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0, help="simulated seconds per run")
    ap.add_argument("--boards", default=",".join(MACHINES), help="emulated boards, comma-separated")
    ap.add_argument("--no-uart", action="store_true", help="skip the UART baseline (slow)")
    args = ap.parse_args()
    boards = [b for b in args.boards.split(",") if b]
    print(
        "| model | rate | board | samples | SIL samples/s | PIL file feed samples/s (x real time) "
        "| PIL UART + recorder samples/s (x real time) | feed/UART | PIL == SIL |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        for label, path in models(tmp):
            model = load_model(path)
            run = simulate(model, "vehicle", args.seconds, seed=3)
            n = len(run.t)
            man = manifest(model.source)
            stim = hil.stimulus(man, run)
            hil.run_sil(model, stim)  # build once, outside the timing
            t_sil = best_of(lambda: decode_all(man, hil.run_sil(model, stim)), 3)  # noqa: B023
            sil = hil.run_sil(model, stim)
            rate = model.rate_hz
            for board in boards:
                firmware_images(board, model.source)  # build outside the timing too
                feed, tel_feed = pil_rate(model, stim, n, board, "feed", tmp)
                same = tel_feed == sil
                uart_col, ratio = "-", "-"
                if not args.no_uart:
                    uart, tel_uart = pil_rate(model, stim, n, board, "uart", tmp)
                    same = same and tel_uart == sil
                    uart_col, ratio = f"{uart:,.0f} ({uart / rate:.1f}x)", f"{feed / uart:.0f}"
                print(
                    f"| {label} | {rate:g} Hz | {board} | {n} | {n / t_sil:,.0f} | {feed:,.0f} ({feed / rate:.1f}x) "
                    f"| {uart_col} | {ratio} | {'yes' if same else 'NO'} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
