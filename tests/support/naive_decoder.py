"""The frame-by-frame reference decoder: the tests' second oracle for :mod:`accelnav.link.decoder` and the
decode benchmark's baseline.

Straightforward on purpose: ``bytes.split``, a Python COBS loop, ``zlib.crc32``, ``struct.unpack_from``,
the loss rule stepped frame by frame, the compact mode's blocks replayed one sample at a time.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

from accelnav.link.accounting import SampleOrder
from accelnav.link.codec import cobs_decode
from accelnav.link.manifest import Manifest

_STRUCT = {"u8": "B", "u16": "H", "u32": "I", "i32": "i", "i64": "q"}


def decode_naive(
    man: Manifest, data: bytes, counts: dict | None = None, replay=None
) -> tuple[dict[str, list[tuple]], int]:
    """Frame-by-frame reference decode: ({frame: [field tuples]}, lost). The benchmark's baseline.
    ``counts``, if given, receives ``lost`` and ``duplicates`` (and the compact mode's counts).
    Compact mode: block frames become sample rows (tuples like a sample frame's) sample by sample, the
    filter stepped one sample at a time (:func:`_naive_rows`)."""
    fmts = {}
    for name in man.up():
        fr = man.frames[name]
        parts = []
        for f in fr["fields"]:
            kind = f["kind"]
            if kind.startswith("u8["):
                parts.append(f"{kind[3:-1]}s")
            elif "[" in kind:
                parts.append(kind[kind.index("[") + 1 : -1] + _STRUCT[kind.split("[")[0]])
            else:
                parts.append(_STRUCT[kind])
        fmts[fr["type"]] = (name, struct.Struct("<B" + "".join(parts)), fr["size"])
    compact = []  # (frame number, name, record) of block and checkpoint frames
    out: dict[str, list[tuple]] = {n: [] for n in man.up()}
    order = SampleOrder(1 << man.flags["reset"], man.frames["cmd_stop"]["type"])
    names = {n: [f["name"] for f in man.frames[n]["fields"]] for n in ("sample", "ack")}
    i_seq, i_index, i_flags = (1 + names["sample"].index(k) for k in ("seq", "index", "flags"))
    i_cmd, i_aindex = (1 + names["ack"].index(k) for k in ("command", "index"))
    ck_names = [f["name"] for f in man.frames["checkpoint"]["fields"]] if "checkpoint" in man.frames else []
    i_cseq = 1 + ck_names.index("seq") if ck_names else None
    segments = data.split(b"\0")[:-1]  # the piece after the last delimiter is unfinished
    for seg in segments:
        if not seg:
            continue
        raw = cobs_decode(seg)
        if raw is None or len(raw) < 5:
            continue
        payload, crc = raw[:-4], int.from_bytes(raw[-4:], "little")
        if zlib.crc32(payload) != crc:
            continue
        kind = fmts.get(payload[0])
        if kind is None or len(payload) != kind[2]:
            continue
        rec = kind[1].unpack_from(payload)
        if kind[0] == "sample" and not order.step(rec[i_seq], rec[i_index], rec[i_flags]):
            continue
        if kind[0] == "ack":
            order.ack(rec[i_cmd], rec[i_aindex])
        if kind[0] == "checkpoint":
            order.compact(rec[i_cseq], rec[1])
        if kind[0] in ("block", "checkpoint"):
            if kind[0] == "block" and not 1 <= rec[3] <= man.data["block_samples"]:
                continue
            if kind[0] == "checkpoint" and not man.checkpoints_sane([rec[3]], [np.frombuffer(rec[-1], np.uint8)])[0]:
                continue
            compact.append((len(out["sample"]), kind[0], rec))
        out[kind[0]].append(rec)
    lost, dups, extra = order.lost, order.duplicates, {}
    if compact:
        rows, extra = _naive_rows(man, compact, replay)
        lost += extra["lost"]
        dups += extra["duplicates"]
        # a compact row whose block came after p sample frames goes before sample frame p (stream order)
        merged = [(i, 1, r) for i, r in enumerate(out["sample"])] + [(p, 0, r) for p, r in rows]
        out["sample"] = [r for _, _, r in sorted(merged, key=lambda x: (x[0], x[1]))]
    if counts is not None:
        counts.update(extra)
        counts.update(lost=lost, duplicates=dups)
    return out, lost


def _naive_rows(man: Manifest, frames: list, replay) -> tuple[list, dict]:
    """Sample rows from block and checkpoint frames, one sample at a time (the oracle of
    :class:`accelnav.link.compact.CompactStream`, which does the same by stretches)."""
    from accelnav.link.compact import CompactStream

    cs = CompactStream(man, replay)
    B, n_ax, raw = cs.B, len(man.axes), man.raw_fields()
    blocks = [r for _, k, r in frames if k == "block"]
    cks = [r for _, k, r in frames if k == "checkpoint"]
    kinds, ids, nb, nc = [], [], 0, 0
    for _, k, _ in frames:
        kinds.append(0 if k == "block" else 1)
        ids.append(nb if k == "block" else nc)
        nb, nc = (nb + 1, nc) if k == "block" else (nb, nc + 1)
    # block tuple: type, index, flags, n, run, 5 counters, aflags (bytes, or B values past 4 axes), then
    # per axis and raw field B values; checkpoint: type, index, flags, axis, run, paused_at, seq, state
    i_af = 10
    wide = not isinstance(blocks[0][i_af], bytes) if blocks else False
    base0 = i_af + B if wide else i_af + 1
    aflags = [r[i_af : i_af + B] if wide else r[i_af] for r in blocks]
    bpos = [p for p, k, _ in frames if k == "block"]
    states = [r[7] for r in cks]
    acc, breaks, events = cs.order(
        kinds, ids, [r[1] for r in blocks], [r[3] for r in blocks], [r[2] for r in blocks],
        [r[1] for r in cks], [r[2] for r in cks], [r[3] for r in cks], [np.frombuffer(s, np.uint8) for s in states],
        None, [r[4] for r in blocks], [r[4] for r in cks], [r[5] for r in cks],
    )  # fmt: skip
    if cs.defer is not None:  # the stream's last frame, never confirmed: damage
        cs.damaged += 1
    samples = []  # (block number, slot)
    for i in acc:
        samples += [(i, k) for k in range(blocks[i][3])]
    N = len(samples)
    ok = [True] * N
    mism = [False] * N
    codes_at = (aflags, base0)
    x = [
        _naive_axis(man, cs, replay, j, events[j], breaks, samples, blocks, codes_at, states, ok, mism)
        for j in range(n_ax)
    ]
    if replay is None:
        cs.unreplayed += N
    else:
        cs.lost += ok.count(False)
    per_code = man.code_flags()
    rows = []
    stype = man.frames["sample"]["type"]
    for p in range(N):
        if not ok[p] or replay is None:
            continue
        b, k = samples[p]
        blk = blocks[b]
        index = blk[1] + k
        fl = blk[2] if k == 0 else blk[2] & ~(cs.R | cs.X)
        fl |= cs.REPLAYED | (cs.MISMATCH if mism[p] else 0)
        row = [stype, index & 0xFFFF, index, fl, *blk[5:10]]
        for j in range(n_ax):
            base = base0 + j * len(raw) * B
            row.append(per_code[(aflags[b][k] >> (2 * j)) & 3])
            row += [blk[base + m * B + k] for m in range(len(raw))]
            row += [int(v) for v in x[j][p]]
        rows.append((bpos[b], tuple(row)))
    return rows, {
        "lost": cs.lost,
        "duplicates": cs.duplicates,
        "checkpoints": cs.checkpoints,
        "mismatches": cs.mismatches,
        "checkpoint_repeats": cs.checkpoint_repeats,
        "unreplayed": cs.unreplayed,
        "damaged": cs.damaged,
    }


def _naive_axis(man, cs, replay, j, events, breaks, samples, blocks, codes_at, states, ok, mism) -> list:
    """Axis j's states, one sample at a time: each stretch replayed from its checkpoint, each checkpoint
    that closes one held against the replay (counts into ``cs``; ``ok`` cleared for a sample without a
    state, ``mism`` set for the stretch of a mismatch). ``codes_at``: (axis codes per block, where the
    raw inputs start in a block tuple)."""
    aflags, base0 = codes_at
    raw, B, N = man.raw_fields(), cs.B, len(samples)
    x = [None] * N
    breakset = set(breaks)
    nbj = cs.state_bytes[j]
    ev_at: dict[int, list] = {}
    for p, i, verify, sync in events:
        ev_at.setdefault(p, []).append((i, verify, sync))
    st, since = None, []
    for p in range(N + 1):
        for i, verify, _ in ev_at.get(p, []):  # checkpoints closing the stretch that ends here
            if verify and st is not None:
                if st == states[i][:nbj]:
                    cs.checkpoints += 1
                else:
                    cs.mismatches += 1
                    for q in since:
                        mism[q] = True
        if p in breakset:
            st, since = None, []
        for i, _, sync in ev_at.get(p, []):
            if sync:
                st, since = states[i][:nbj], []
        if p == N:
            break
        if st is None or replay is None:
            ok[p] = False
            continue
        b, k = samples[p]
        blk = blocks[b]
        code = (aflags[b][k] >> (2 * j)) & 3
        base = base0 + j * len(raw) * B
        in1 = np.array([blk[base + k]], np.uint32)
        in2 = np.array([blk[base + B + k]], np.uint32) if len(raw) > 1 else None
        one = np.zeros(1, man.dtypes["sample"])
        fin, nbad = replay.run(
            j, np.zeros(1, np.int64), np.ones(1, np.int64), np.frombuffer(st, np.uint8), [code], in1, in2, one
        )
        ax = man.axes[j]
        xs = [[int(one[f"{ax}.{c}"][0]) for c in "ruae"]]
        if nbad[0]:
            cs.mismatches += int(nbad[0])
            for q in [*since, p]:
                mism[q] = True
        st = fin[0].tobytes()
        since.append(p)
        x[p] = xs[0]
    return x
