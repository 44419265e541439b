"""Loss accounting of a link: which sample frames to deliver, how many were lost or repeated, and the
counts a user is shown.

Sample frames carry a 16-bit sequence number that the MCU increments for every sample frame it means
to send and the 32-bit sample index; :class:`SampleOrder` drops a repeated or older frame (counted in
``duplicates``, never delivered twice) and counts the frames missing in a gap exactly, the index
telling how many times seq wrapped. :class:`Stats` holds a decoder's counts; :func:`link_counts` and
:func:`format_counts` are the one way the recorder and ``accelnav log info`` show them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_WRAP = 1 << 16
_HALF = 1 << 15


class SampleOrder:
    """Exact accounting of sample frames from their ``seq`` (u16, one per frame the MCU meant to send)
    and ``index`` (u32, the sample index): which frames to deliver, how many were lost, how many repeated.

    A frame whose index is not past the last delivered one is a repeat or an older frame: dropped and
    counted in ``duplicates`` (never delivered twice), unless it is a firmware reset (the index restarts
    at 0, seq runs on): seq 1..32767 ahead, the index step not what the seq step back says (within 16
    frames, modulo 2^16), and either the reset flag or an index below what those seq steps take a fresh
    start to; for 16384 frames after it a frame from before that reset is a repeat too.

    For a frame with a later index the number of frames sent since the last delivered one is
    ``a + 65536 k`` with ``a`` the seq step modulo 2^16 and ``k`` chosen so that it is nearest to the
    index step divided by the decimation (the index step of the last one-frame step): gaps of any
    length are counted exactly as long as the decimation did not change and the MCU missed fewer than
    32768 frames' worth of samples inside the gap. After a frame flagged as the first after a filter
    reset, or a ``stop`` acknowledged inside the gap (the index runs on while stopped, seq does not),
    the seq step alone counts (k = 0); a stop of D frame periods whose ack was lost adds
    65536 round(D / 65536) lost frames (none below 32768).

    :meth:`step` is the rule frame by frame (the tests' naive decoder); :meth:`run` applies it to a batch
    with numpy between the irregular frames (index not later, reset flag, stop), which it steps.
    """

    def __init__(self, reset_mask: int = 1 << 2, stop_command: int = 0x11):
        self.reset_mask = reset_mask
        self.stop_command = stop_command
        self.last_seq: int | None = None
        self.last_index: int | None = None
        self.decimation: int | None = None  # index step of the last one-frame step
        self.stops: list[int] = []  # indices of acknowledged stops not yet passed
        # after a reset: (seq of its first frame, seq, index and decimation of the last frame before it)
        self.before_reset: tuple[int, int, int, int] | None = None
        self._since_reset = 0
        self.mark: tuple[int, int] | None = None  # (seq, index) the next sample frame starts from
        self.closed = False  # seq counted up to a compact checkpoint: no sample frame delivered since
        self.lost = 0
        self.duplicates = 0

    def compact(self, seq: int | None, index: int) -> None:
        """A compact-mode checkpoint, in stream order with the sample frames: the firmware had sent sample
        frames up to ``seq`` (the next one's) when the compact stream reached ``index``. The first sample
        frame after it counts the frames it missed from there (a mode change whose first frames were lost),
        however long the compact stretch was. The sample frames missing before it (the last ones of the state
        mode) are counted here from ``seq`` alone (the index may be damage the compact rule refuses later),
        as no sample frame may follow (a recording that ends in the compact mode): seq then stands at the
        frame before the checkpoint (``closed``), so that a missing frame turning up late is an older frame,
        not 65535 more lost."""
        if seq is None:
            self.mode_end(index)
            return
        if self.last_index is None or index > self.last_index:
            self.mark = (seq, index)
            if self.last_seq is not None and 0 < (seq - self.last_seq) % _WRAP < _HALF:
                self.lost += (seq - 1 - self.last_seq) % _WRAP
                self.last_seq = (seq - 1) % _WRAP
                self.decimation, self.stops = None, []
                self.closed = True

    def mode_end(self, index: int) -> None:
        """The ack of a change to the compact mode at ``index``: the state mode's sample frames ended at the one
        of ``index - 1``. Those after the last delivered are counted lost here when each sample had its frame
        (decimation 1 and no stop since), since the compact mode's checkpoints, which would say it by seq,
        may never come (a stream cut short)."""
        if self.last_index is None or self.closed or self.stops or self.decimation != 1:
            return
        n = index - 1 - self.last_index
        if 0 < n < _HALF:
            self.lost += n
            self.last_seq, self.last_index = (self.last_seq + n) % _WRAP, index - 1
            self.closed = True

    def ack(self, command: int, index: int) -> None:
        """An ack frame, in stream order with the sample frames."""
        if command == self.stop_command:
            self.stops.append(index)

    def _paused(self, index: int) -> bool:
        last = self.last_index
        paused = any(last < s <= index for s in self.stops)
        self.stops = [s for s in self.stops if s > index]
        return paused

    def step(self, seq: int, index: int, flags: int) -> bool:
        """One accepted sample frame, in stream order: True to deliver it."""
        if self.mark is not None and index >= self.mark[1]:
            ms, mi = self.mark
            self.mark = None
            if self.last_index is None or mi > self.last_index:
                self.lost += (seq - ms) % _WRAP  # the frames sent between the compact stretch and this one
                self.last_seq, self.last_index = seq, index
                self.decimation, self.stops, self.closed = None, [], False
                return True
        if self.closed and index > self.last_index and not 1 <= (seq - self.last_seq) % _WRAP < _HALF:
            self.duplicates += 1  # a frame counted lost at a checkpoint after it, arriving late
            return False
        self.closed = False
        if self.last_seq is None:
            self.last_seq, self.last_index = seq, index
            return True
        a = (seq - self.last_seq) % _WRAP
        di = index - self.last_index
        ahead = 1 <= a < _HALF
        if di <= 0:
            # a firmware reset (the index started again at 0) if seq is ahead and the index no further than
            # those seq steps take it; otherwise a repeat of an earlier frame
            d = self.decimation or 1
            back = (-di / d - (_WRAP - a) + _HALF) % _WRAP - _HALF  # 0 for an older frame (modulo 2^16 frames)
            older = abs(back) <= 16
            if older or not (ahead and (flags & self.reset_mask or index < a * d)):
                self.duplicates += 1
                return False
            n = a
            self._reset(seq)
        elif self.before_reset and self._before(seq, index):
            self.duplicates += 1  # a repeat of a frame from before the last reset
            return False
        elif flags & self.reset_mask and ahead:
            n = a
            self._reset(seq)
        elif self._paused(index):
            n = a if a else _WRAP
        else:
            d = self.decimation
            k = max(0, round((di / d - a) / _WRAP)) if d else 0
            if a == 0:
                k = max(k, 1)
            n = a + _WRAP * k
            if a == 1:
                self.decimation = di
        self.lost += n - 1
        self.last_seq, self.last_index = seq, index
        if self.before_reset:
            self._since_reset += 1
            if self._since_reset > 16384:
                self.before_reset = None  # far enough into the new run: no repeats from before it any more
        return True

    def _reset(self, seq: int) -> None:
        self.before_reset = (seq, self.last_seq, self.last_index, self.decimation or 1)
        self._since_reset = 0
        self.decimation, self.stops = None, []

    def _before(self, seq: int, index: int) -> bool:
        """Is (seq, index) a frame from before the last reset (seq and index steps back agree)?"""
        _, ls, li, d = self.before_reset
        back = (ls - seq) % _WRAP
        return index <= li and back < _HALF and abs(((li - index) / d - back + _HALF) % _WRAP - _HALF) <= 16

    def run(self, seq, index, flags, stops: list[tuple[int, int]] = (), marks: list = ()) -> np.ndarray:
        """:meth:`step` over arrays (stream order), vectorised between irregular frames: the keep mask.
        ``stops``: (number of these sample frames before the ack in the stream, index) of stop acks;
        ``marks``: (number of sample frames before it, seq, index) of compact checkpoints (:meth:`compact`), seq
        None for the ack of a change to the compact mode (:meth:`mode_end`)."""
        n = len(seq)
        keep = np.ones(n, bool)
        marks = sorted(marks, key=lambda m: m[0])
        if n == 0:
            for _, s in stops:
                self.stops.append(s)
            for _, ms, mi in marks:
                self.compact(ms, mi)
            return keep
        seq = seq.astype(np.int64)
        index = index.astype(np.int64)
        flags = flags.astype(np.int64)
        regular = np.zeros(n, bool)  # later index than the previous frame, no reset flag, no stop between
        regular[1:] = index[1:] > index[:-1]
        regular &= (flags & self.reset_mask) == 0
        prev = np.empty(n, np.int64)
        prev[0] = -1
        prev[1:] = index[:-1]
        for p, s in [(0, s) for s in self.stops] + list(stops):
            hit = (prev < s) & (s <= index)
            hit[:p] = False
            regular &= ~hit
        for p, _, _ in marks:
            if p < n:
                regular[p] = False
        pending = sorted(stops)
        irregular = np.flatnonzero(~regular)
        i = 0
        while i < n:
            while pending and pending[0][0] <= i:
                self.stops.append(pending.pop(0)[1])
            while marks and marks[0][0] <= i:
                self.compact(*marks.pop(0)[1:])
            keep[i] = self.step(int(seq[i]), int(index[i]), int(flags[i]))
            i += 1
            if not keep[i - 1] or i == n or self.before_reset:
                continue
            nb = irregular[np.searchsorted(irregular, i)] if irregular.size and irregular[-1] >= i else n
            if pending:
                nb = min(nb, max(pending[0][0], i))
            if marks:
                nb = min(nb, max(marks[0][0], i))
            if nb > i:
                self._regular(seq[i - 1 : nb], index[i - 1 : nb])
                i = nb
        for _, s in pending:
            self.stops.append(s)
        for _, ms, mi in marks:
            self.compact(ms, mi)
        return keep

    def _regular(self, s: np.ndarray, x: np.ndarray) -> None:
        """Frames s[1:], x[1:] after the delivered s[0], x[0], every index later than the one before."""
        a = np.diff(s) % _WRAP
        di = np.diff(x)
        one = a == 1
        pos = np.where(one, np.arange(a.size), -1)
        last_one = np.maximum.accumulate(pos)
        prev_one = np.empty_like(last_one)
        prev_one[0] = -1
        prev_one[1:] = last_one[:-1]
        d = np.where(prev_one >= 0, di[np.maximum(prev_one, 0)], self.decimation or 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(d > 0, np.rint((di / np.where(d > 0, d, 1) - a) / _WRAP), 0).astype(np.int64)
        k = np.maximum(k, 0)
        k = np.where(a == 0, np.maximum(k, 1), k)
        self.lost += int((a + _WRAP * k - 1).sum())
        if last_one[-1] >= 0:
            self.decimation = int(di[last_one[-1]])
        self.last_seq, self.last_index = int(s[-1]), int(x[-1])


@dataclass
class Stats:
    frames: dict[str, int] = field(default_factory=dict)
    lost: int = 0  # sample frames missing between delivered ones
    duplicates: int = 0  # sample frames dropped as repeated or older than the last delivered one
    bad_frames: int = 0  # delimited segments refused (length, COBS, type, CRC, contents no firmware sends)
    crc_errors: int = 0  # of those: right length and COBS, wrong CRC
    garbage_bytes: int = 0  # bytes in refused segments
    bytes: int = 0
    # compact mode (block and checkpoint frames); lost and duplicates count its samples
    checkpoints: int = 0  # checkpoints the replay matched bit for bit
    mismatches: int = 0  # checkpoints the replay did not match (and stretches whose step verdicts differed)
    checkpoint_repeats: int = 0  # repeated or older checkpoints, ignored
    unreplayed: int = 0  # samples received without a replay to give them states (no model text)

    def as_dict(self) -> dict:
        return {
            "frames": dict(self.frames),
            "lost": self.lost,
            "duplicates": self.duplicates,
            "bad_frames": self.bad_frames,
            "crc_errors": self.crc_errors,
            "garbage_bytes": self.garbage_bytes,
            "bytes": self.bytes,
            "checkpoints": self.checkpoints,
            "mismatches": self.mismatches,
            "checkpoint_repeats": self.checkpoint_repeats,
            "unreplayed": self.unreplayed,
        }


def link_counts(stats: Stats | dict) -> dict:
    """The counts a user is shown for a link or a log: the one definition the recorder's summary and
    ``accelnav log info`` both print."""
    s = stats.as_dict() if isinstance(stats, Stats) else stats
    return {
        "samples": int(s["frames"].get("sample", 0)),
        "lost": s["lost"],
        "duplicates": s["duplicates"],
        "damaged_frames": s["bad_frames"],
        "crc_errors": s["crc_errors"],
        "garbage_bytes": s["garbage_bytes"],
        **(
            {k: s[k] for k in ("checkpoints", "mismatches", "checkpoint_repeats", "unreplayed")}
            if s["frames"].get("block")
            else {}
        ),
    }


def format_counts(c: dict) -> str:
    """:func:`link_counts` as the one line both the recorder and ``log info`` print."""
    text = (
        f"{c['samples']} samples, lost {c['lost']}, duplicates {c['duplicates']}, "
        f"damaged {c['damaged_frames']} frames (CRC errors {c['crc_errors']}, {c['garbage_bytes']} bytes)"
    )
    if "checkpoints" in c:
        text += f"; replay: {c['checkpoints']} checkpoints matched, {c['mismatches']} mismatches"
        if c["unreplayed"]:
            text += f", {c['unreplayed']} samples unreplayed (no model text)"
    return text
