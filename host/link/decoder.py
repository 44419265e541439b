"""The streaming telemetry decoder: bytes in chunks of any size, frames out as numpy structured arrays.

A :class:`Decoder` takes the byte stream in chunks (a serial read, a log chunk, a whole file) and
returns the frames completed in that chunk, one structured array per frame type, whose field names
are the manifest's (``seq``, ``index``, ``x.code``, ``x.r`` ...). It resynchronises at the next 0x00
after any garbage and counts what it refused.

Vectorised: every frame of a type has the same length on the wire (frames are shorter than 254
bytes, so COBS adds exactly one byte), so a chunk is cut at its zero bytes with one ``flatnonzero``
and the candidate frames of each length go through the codec's row kernels (:mod:`accelnav.link.codec`)
or, where a C compiler is found, one call of a small C kernel (:mod:`accelnav.link.wirekernel`, the
same results, several times faster on long frames). Nothing loops over frames in Python.

Compact mode (block and checkpoint frames, see :mod:`accelnav.codegen.frames`): the decoder turns them
into sample rows of the same dtype as the sample frame, their states from the replay of the
firmware's own filter (:mod:`accelnav.link.replay`, given to :class:`Decoder`), every checkpoint held
against the replay bit for bit, losses and repeats counted in samples from the 32-bit index
(:mod:`accelnav.link.compact`). Losses of sample frames: :mod:`accelnav.link.accounting`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .accounting import SampleOrder, Stats
from .codec import cobs_decode_rows, crc_rows
from .compact import concat_records
from .manifest import Manifest
from .wirekernel import decode_frames


@dataclass
class Batch:
    """Frames completed by one feed(): per up-frame type a structured array, in stream order."""

    frames: dict[str, np.ndarray]
    lost: int = 0

    def __getitem__(self, name: str) -> np.ndarray:
        return self.frames[name]


# the counts CompactStream keeps that the decoder's Stats carry under the same names
_COMPACT_COUNTS = ("lost", "duplicates", "mismatches", "checkpoints", "checkpoint_repeats", "unreplayed")


class Decoder:
    """Streaming, vectorised decoder of the frames in ``manifest``; see the module docstring."""

    def __init__(self, manifest: Manifest, directions: tuple[str, ...] = ("up",), replay=None, kernel: bool = True):
        """``replay``: an :class:`accelnav.link.replay.Replay` of the firmware's filter, which the compact
        mode's block frames need to become sample rows (:func:`replay_for` builds one from a model).
        ``kernel``: COBS and CRC through the C kernel of :mod:`accelnav.link.wirekernel` when it can be
        built here (else, or with False, the numpy path)."""
        self.man = manifest
        self._wire = None
        if kernel:
            from .wirekernel import wire_lib

            self._wire = wire_lib()
        self.names = [n for n, f in manifest.frames.items() if f["direction"] in directions]
        self.by_len: dict[int, list[str]] = {}
        for n in self.names:
            self.by_len.setdefault(manifest.frames[n]["size"] + 5, []).append(n)
        self.max_len = max(self.by_len)
        self._tail = b""
        self._overlong = False  # the tail exceeded every frame length: the segment is refused at its delimiter
        self.order = SampleOrder(1 << manifest.flags["reset"], manifest.frames["cmd_stop"]["type"])
        self.mode_compact = manifest.frames.get("cmd_mode_compact", {}).get("type")
        self.stats = Stats(frames={n: 0 for n in self.names})
        self.compact = None
        if "block" in self.names and "checkpoint" in self.names:
            from .compact import CompactStream

            self.compact = CompactStream(manifest, replay)

    def feed(self, data: bytes) -> Batch:
        self.stats.bytes += len(data)
        buf = self._tail + bytes(data)
        arr = np.frombuffer(buf, np.uint8)
        zeros = np.flatnonzero(arr == 0)
        empty = {n: np.zeros(0, self.man.dtypes[n]) for n in self.names}
        if zeros.size == 0:
            self._keep_tail(buf)
            return Batch(empty)
        starts = np.empty(zeros.size, np.int64)
        starts[0] = 0
        starts[1:] = zeros[:-1] + 1
        lengths = zeros - starts
        if self._overlong:  # the first segment began before the kept tail: refused, counted at its full length
            self.stats.garbage_bytes += int(lengths[0]) - (self.max_len + 1)  # (the dropped part: _keep_tail)
            lengths[0] = self.max_len + 1
            self._overlong = False
        self._keep_tail(buf[zeros[-1] + 1 :])

        keep = lengths > 0
        starts, lengths = starts[keep], lengths[keep]
        order_parts, name_parts, rec_parts = [], [], []
        accepted = np.zeros(starts.size, bool)
        for L, names in self.by_len.items():
            sel = np.flatnonzero(lengths == L)
            if sel.size == 0:
                continue
            m = L - 1
            if self._wire is not None:
                dec, ok, crc_ok = decode_frames(self._wire, arr, starts[sel], L)
            else:
                rows = np.lib.stride_tricks.sliding_window_view(arr, L)[starts[sel]]  # one row copy per frame
                dec, ok = cobs_decode_rows(rows)
                crc_ok = crc_rows(dec[:, : m - 4]) == dec[:, m - 4 :].copy().view("<u4").ravel()
            type_ok = np.zeros(sel.size, bool)
            for n in names:
                type_ok |= dec[:, 0] == self.man.frames[n]["type"]
            self.stats.crc_errors += int(np.count_nonzero(ok & type_ok & ~crc_ok))
            good = ok & crc_ok & type_ok
            accepted[sel[good]] = True
            for n in names:
                g = good & (dec[:, 0] == self.man.frames[n]["type"])
                if g.any():
                    recs = np.ascontiguousarray(dec[g, : m - 4]).view(self.man.dtypes[n]).ravel()
                    sane = self._sane(n, recs)
                    if not sane.all():  # a right CRC on contents no firmware sends: refused as damaged
                        drop = np.flatnonzero(g)[~sane]
                        recs = recs[sane]
                        g[drop] = False
                        accepted[sel[drop]] = False
                    order_parts.append(sel[g])
                    name_parts.append(n)
                    rec_parts.append(recs)
        refused = ~accepted
        self.stats.bad_frames += int(np.count_nonzero(refused))
        self.stats.garbage_bytes += int(lengths[refused].sum())
        out = dict(empty)
        where = {}
        for n, o, r in zip(name_parts, order_parts, rec_parts, strict=True):
            k = np.argsort(o, kind="stable")
            out[n], where[n] = r[k], o[k]  # stream order
        lost = self._account(out, where)
        if self.compact is not None:
            lost += self._compact(out, where)
        for n in out:
            self.stats.frames[n] += len(out[n])
        return Batch(out, lost)

    def _account(self, out: dict, where: dict) -> int:
        """Drop repeated sample frames and count the lost ones (:class:`SampleOrder`)."""
        if "sample" not in out:
            return 0
        stops = []
        acks = out.get("ack")
        if acks is not None and len(acks):
            is_stop = acks["command"] == self.order.stop_command
            if is_stop.any():
                before = np.searchsorted(where.get("sample", np.zeros(0, np.int64)), where["ack"][is_stop])
                stops = list(zip(before.tolist(), acks["index"][is_stop].tolist(), strict=True))
        smp = out["sample"]
        marks = []
        cks = out.get("checkpoint")
        if cks is not None and len(cks):
            before = np.searchsorted(where.get("sample", np.zeros(0, np.int64)), where["checkpoint"])
            marks = list(zip(before.tolist(), cks["seq"].tolist(), cks["index"].tolist(), strict=True))
        if acks is not None and len(acks) and self.mode_compact is not None:
            is_mc = acks["command"] == self.mode_compact
            if is_mc.any():
                before = np.searchsorted(where.get("sample", np.zeros(0, np.int64)), where["ack"][is_mc])
                marks += [(p, None, i) for p, i in zip(before.tolist(), acks["index"][is_mc].tolist(), strict=True)]
        lost0, dup0 = self.order.lost, self.order.duplicates
        keep = self.order.run(smp["seq"], smp["index"], smp["flags"], stops, marks)
        if not keep.all():
            out["sample"] = smp[keep]
            where["sample"] = where["sample"][keep]
        lost = self.order.lost - lost0
        self.stats.lost += lost
        self.stats.duplicates += self.order.duplicates - dup0
        return lost

    def _sane(self, name: str, recs: np.ndarray) -> np.ndarray:
        if name == "block":
            return (recs["n"] >= 1) & (recs["n"] <= self.compact.B)
        if name == "checkpoint":
            return self.man.checkpoints_sane(recs["axis"], recs["state"])
        return np.ones(len(recs), bool)

    def _compact(self, out: dict, where: dict) -> int:
        """Block and checkpoint frames -> sample rows (:class:`accelnav.link.compact.CompactStream`), merged
        with the state mode's sample frames in stream order."""
        c = self.compact
        e = np.zeros(0, np.int64)
        before = {k: getattr(c, k) for k in _COMPACT_COUNTS}
        dmg0 = c.damaged, c.damaged_bytes
        rows, rpos = self._compact_around_states(out, where, e)
        if len(out["sample"]):  # held rows before a state-mode frame go out before it, never after
            early, epos = c.release_before(int(where["sample"][-1]))
            if len(early):
                k = np.argsort(np.r_[rpos, epos], kind="stable")
                rows, rpos = np.concatenate([rows, early])[k], np.r_[rpos, epos][k]
        self.stats.bad_frames += c.damaged - dmg0[0]
        self.stats.garbage_bytes += c.damaged_bytes - dmg0[1]
        if len(rows):
            if len(out["sample"]):
                spos = where["sample"]
                allpos = np.r_[spos, rpos]
                merged = np.concatenate([out["sample"], rows])
                out["sample"] = merged[np.argsort(allpos, kind="stable")]
            else:
                out["sample"] = rows
        for k, b in before.items():  # this batch's counts, added to the decoder's
            setattr(self.stats, k, getattr(self.stats, k) + getattr(c, k) - b)
        return c.lost - before["lost"]

    def _compact_around_states(self, out: dict, where: dict, e: np.ndarray):
        """:meth:`CompactStream.feed` of the batch's block and checkpoint frames, in groups split where the
        state mode's sample frames came between them (:meth:`CompactStream.state_frames` told each time)."""
        c = self.compact
        blk, bpos = out["block"], where.get("block", e)
        cks, cpos = out["checkpoint"], where.get("checkpoint", e)
        spos = where.get("sample", e)
        if not len(spos):
            return c.feed(blk, bpos, cks, cpos)
        sidx = out["sample"]["index"].astype(np.int64)
        gb, gc = np.searchsorted(spos, bpos), np.searchsorted(spos, cpos)  # sample frames before each frame
        rows, rpos, done = [], [], 0
        # group 0 even when empty: the frame an earlier batch left pending and the held rows' positions (from
        # an earlier batch now) are settled before the sample frames move the stream on
        for g in np.unique(np.r_[0, gb, gc]).tolist():
            if g > done:
                c.state_frames(int(sidx[done:g].max()))
                done = g
            r, p = c.feed(blk[gb == g], bpos[gb == g], cks[gc == g], cpos[gc == g], more=bool(rows))
            rows.append(r)
            rpos.append(p)
        if done < len(spos):
            c.state_frames(int(sidx[done:].max()))
        return concat_records(rows, c.sample_dtype), np.concatenate(rpos) if rpos else e

    @property
    def received(self) -> int:
        """Samples received so far, delivered or not yet: sample rows out, plus the compact mode's rows held
        until the checkpoint closing their stretch and its samples with no replay (no model text). What a
        live view counts: rows wait up to a checkpoint interval (2.56 s at 100 Hz) before they go out."""
        n = self.stats.frames.get("sample", 0) + self.stats.unreplayed
        if self.compact is not None:
            n += len(self.compact.held[0])
        return n

    @property
    def mid_frame(self) -> bool:
        """Bytes of a frame whose delimiter has not come yet are held."""
        return bool(self._tail)

    def _keep_tail(self, tail: bytes) -> None:
        if len(tail) > self.max_len:
            self.stats.garbage_bytes += len(tail) - self.max_len
            tail = tail[-self.max_len :]
            self._overlong = True
        self._tail = tail

    @property
    def last_index(self) -> int | None:
        """The index of the last sample received in order (a sample frame, or a block's last sample)."""
        ends = [self.order.last_index]
        if self.compact is not None and self.compact.end is not None:
            ends.append(self.compact.end - 1)
        ends = [e for e in ends if e is not None]
        return max(ends) if ends else None

    def release(self) -> np.ndarray:
        """End of the stream: the compact mode's sample rows still waiting for the checkpoint that closes
        their stretch (replayed but never verified: the stream ended first); they count as delivered."""
        if self.compact is None:
            return np.zeros(0, self.man.dtypes["sample"])
        dmg0 = self.compact.damaged, self.compact.damaged_bytes
        rows = self.compact.release()
        self.stats.bad_frames += self.compact.damaged - dmg0[0]
        self.stats.garbage_bytes += self.compact.damaged_bytes - dmg0[1]
        self.stats.frames["sample"] += len(rows)
        return rows

    def finish(self) -> int:
        """End of stream: the bytes after the last delimiter are an unfinished frame; returns their count."""
        n = len(self._tail)
        if n:
            self.stats.bad_frames += 1
            self.stats.garbage_bytes += n
        self._tail = b""
        return n


def end_of_stream(dec: Decoder) -> np.ndarray:
    """A recording ends: the bytes after the last delimiter refused as an unfinished frame, the compact rows
    still waiting for a checkpoint released (and counted). The recorder and every reader of a log end a
    stream this one way, so that their counts (:func:`link_counts`) agree."""
    dec.finish()
    return dec.release()


def replay_for(man: Manifest, model):
    """The replay of the firmware's filter (a Model or its TOML text) for ``man``'s compact frames;
    None when ``man`` has none or ``model`` is empty."""
    if "block" not in man.frames or not model:
        return None
    from .replay import Replay

    return Replay(man, model)


def decode_all(man: Manifest, data: bytes, replay=None) -> tuple[dict[str, np.ndarray], Stats]:
    """Decode a whole byte string at once (``replay``: see :class:`Decoder`)."""
    d = Decoder(man, replay=replay)
    frames = dict(d.feed(data).frames)
    rest = d.release()
    if len(rest):
        frames["sample"] = np.concatenate([frames["sample"], rest])
    return frames, d.stats
