"""What the live plot costs the recorder, beside the decoding it already does.

The default model's firmware (host board, cffi, state mode) makes ``--seconds`` of telemetry; it is fed to
the recorder's Decoder in ``--piece`` byte reads, once alone (the baseline: the loop today) and once with
LivePlot.push on every batch (the loop with --live-plot). The redraw happens in another thread, so the
recorder pays only the push; the redraw's time is printed too, as the share of one core it takes at the
default refresh.

    .venv/bin/python bench/speed/bench_live_plot.py [--seconds 120] [--piece 4096]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.decoder import Decoder
from accelnav.model.load import load_model
from accelnav.plots.live import REFRESH_S, LivePlot


def _feed(man, data: bytes, piece: int, push) -> tuple[float, int, float]:
    """(seconds, rows, worst push in s) decoding ``data`` read by read, ``push`` on each batch or None."""
    dec = Decoder(man)
    rows = 0
    worst = 0.0
    t0 = time.perf_counter()
    for k in range(0, len(data), piece):
        batch = dec.feed(data[k : k + piece])["sample"]
        rows += len(batch)
        if push is not None and len(batch):
            t1 = time.perf_counter()
            push(batch)
            worst = max(worst, time.perf_counter() - t1)
    return time.perf_counter() - t0, rows, worst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--piece", type=int, default=4096)
    args = ap.parse_args()
    man = manifest(None)
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_command(man, "mode_states"))
    fw.take()
    n = int(args.seconds * man.rate_hz)
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(1).integers(-3, 4, (n, 2))))
    data = fw.take()
    base = min(_feed(man, data, args.piece, None)[0] for _ in range(3))
    runs = []
    for _ in range(3):
        plot = LivePlot(man, load_model())
        runs.append(_feed(man, data, args.piece, plot.push))
    live, rows, worst = min(runs)
    with tempfile.TemporaryDirectory() as tmp:
        draws = []
        for _ in range(5):
            t0 = time.perf_counter()
            plot.save(Path(tmp) / "live.png")
            draws.append(time.perf_counter() - t0)
    draw = float(np.median(draws))
    print(f"stream: {rows} sample frames ({args.seconds:g} s at {man.rate_hz:g} Hz), {len(data)} bytes, "
          f"{args.piece}-byte reads")  # fmt: skip
    print(f"decode alone (baseline, the loop today): {base * 1e3:8.1f} ms  {rows / base:12.0f} frames/s")
    print(f"decode + LivePlot.push (--live-plot):    {live * 1e3:8.1f} ms  {rows / live:12.0f} frames/s")
    print(f"push overhead: {100 * (live - base) / base:+.1f} %; worst single push {worst * 1e6:.0f} us")
    print(f"one redraw (other thread, {plot.capacity}-sample ring): {draw * 1e3:.0f} ms median of 5, "
          f"{100 * draw / REFRESH_S:.0f} % of one core at one redraw per {REFRESH_S:g} s")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
