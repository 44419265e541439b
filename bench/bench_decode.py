"""Telemetry decode throughput, and what the link can carry.

1. A one-hour, two-axis, 1 kHz stream of sample frames (3.6 million frames of the
   default model's layout, plausible contents, a few damaged frames) is decoded
   by accelnav.link.telemetry.Decoder (vectorised, fed in 1 MiB pieces as a log is read)
   and by decode_naive (a straightforward frame-by-frame Python decode: split,
   COBS loop, zlib.crc32, struct.unpack) in the same run. Both must agree; the
   figures are printed side by side, nothing is asserted about speed.
2. Bytes per sample on the wire for both example models, and the decimation each
   link rate needs at 100 Hz and 1 kHz.

    .venv/bin/python bench/bench_decode.py [--minutes 60] [--rate 1000]
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np

from accelnav.hil_sim.firmware import DUTY_MODEL, generated
from accelnav.link.telemetry import Decoder, Manifest, decode_naive, encode_frames

BAUDS = (115200, 230400, 460800, 921600)


def make_stream(man: Manifest, n: int, rng) -> bytes:
    """n sample frames: random-walk states in their Q formats, codes near mid-scale, seq/index counting."""
    out = []
    block = 200_000
    for a in range(0, n, block):
        m = min(block, n - a)
        rec = np.zeros(m, man.dtypes["sample"])
        idx = np.arange(a, a + m)
        rec["seq"] = idx % 65536
        rec["index"] = idx
        rec["flags"] = 1
        for ax in man.axes:
            rec[f"{ax}.code"] = 2048 + rng.integers(-200, 200, m)
            for s, scale in (("r", 50.0), ("u", 5.0), ("a", 2.0), ("e", 0.1)):
                frac = man.field("sample", f"{ax}.{s}")["frac"]
                kind = man.field("sample", f"{ax}.{s}")["kind"]
                v = np.cumsum(rng.normal(0, scale / 300, m)) + rng.normal(0, scale)
                lim = 2.0 ** (31 if kind == "i32" else 63) - 1
                rec[f"{ax}.{s}"] = np.clip(np.ldexp(v, frac), -lim, lim).astype(np.int64)
        out.append(encode_frames(man, "sample", rec))
    return b"".join(out)


def repeat_chunks(data: bytes, wire: int, rng, n: int) -> bytes:
    """Repeat ``n`` runs of 1..50 frames right after themselves (a USB-serial adapter's buffer replayed)."""
    n_frames = len(data) // wire
    ends = np.sort(rng.integers(50, n_frames, n))
    parts, at = [], 0
    for e in ends.tolist():
        k = int(rng.integers(1, 51))
        parts += [data[at * wire : e * wire], data[(e - k) * wire : e * wire]]
        at = e
    parts.append(data[at * wire :])
    return b"".join(parts)


def damage(data: bytes, rng, n_hits: int) -> bytes:
    buf = bytearray(data)
    for pos in rng.integers(0, len(buf), n_hits):
        buf[pos] ^= 0x5A
    return bytes(buf)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=1000.0, help="sample rate of the stream, Hz")
    ap.add_argument("--piece", type=int, default=1 << 20, help="bytes per Decoder.feed()")
    ap.add_argument("--repeats", type=int, default=100, help="runs of 1..50 frames repeated in the stream")
    args = ap.parse_args(argv)

    man = Manifest(json.loads(generated(None)["acnframe.json"]))
    n = int(args.minutes * 60 * args.rate)
    rng = np.random.default_rng(1)
    t = time.perf_counter()
    wire = man.frames["sample"]["wire_size"]
    data = damage(repeat_chunks(make_stream(man, n, rng), wire, rng, args.repeats), rng, 100)
    t_make = time.perf_counter() - t
    print(
        f"stream: {n:,} frames ({args.minutes:g} min at {args.rate:g} Hz, {len(man.axes)} axes), "
        f"{len(data) / 1e6:.1f} MB, {args.repeats} repeated runs of frames, 100 damaged bytes; "
        f"made in {t_make:.1f} s"
    )

    t = time.perf_counter()
    dec = Decoder(man)
    seqs = []
    for a in range(0, len(data), args.piece):
        seqs.append(dec.feed(data[a : a + args.piece])["sample"]["seq"])
    dec.finish()
    t_vec = time.perf_counter() - t
    got = int(sum(len(s) for s in seqs))

    t = time.perf_counter()
    counts = {}
    naive, naive_lost = decode_naive(man, data, counts)
    t_naive = time.perf_counter() - t
    assert got == len(naive["sample"]) and dec.stats.lost == naive_lost, "the two decoders disagree"
    assert dec.stats.duplicates == counts["duplicates"], "the two decoders disagree on duplicates"
    assert np.array_equal(np.concatenate(seqs), np.array([r[1] for r in naive["sample"]], dtype=np.uint16))

    print()
    print(f"{'decoder':<34}{'seconds':>9}{'frames/s':>14}{'MB/s':>9}{'x realtime':>12}")
    for name, secs in (
        ("vectorised (link.telemetry.Decoder)", t_vec),
        ("naive frame-by-frame (baseline)", t_naive),
    ):
        print(f"{name:<34}{secs:9.2f}{got / secs:14,.0f}{len(data) / 1e6 / secs:9.1f}{n / args.rate / secs:12,.0f}")
    print(
        f"speed-up: {t_naive / t_vec:.1f}x; both: {got:,} frames accepted, {dec.stats.lost} lost, "
        f"{dec.stats.duplicates} duplicates dropped, {dec.stats.crc_errors} CRC errors, "
        f"{dec.stats.bad_frames} refused"
    )

    print("\nbytes per sample on the wire (COBS + CRC-32 + delimiter) and the decimation a link needs")
    print(f"{'model':<20}{'bytes':>6}" + "".join(f"{b:>10} Bd" for b in BAUDS))
    for label, path in (("adxl250 (2 analog)", None), ("adxl202 (2 duty)", str(DUTY_MODEL))):
        m = json.loads(generated(path)["acnframe.json"])
        wire = m["frames"]["sample"]["wire_size"]
        fps = [b / 10 / wire for b in BAUDS]  # 8N1: 10 bits a byte
        print(f"{label:<20}{wire:>6}" + "".join(f"{f:10.0f} f/s" for f in fps))
        for rate in (100.0, 1000.0):
            print(
                f"{'  decimation @ ' + format(rate, 'g') + ' Hz':<26}"
                + "".join(f"{math.ceil(rate / f):>14d}" for f in fps)
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
