"""Sample rows from the compact mode's block and checkpoint frames (see :mod:`accelnav.codegen.frames`).

:class:`CompactStream` takes the block and checkpoint frames a decoder
accepted, in stream order, batch after batch, and returns the sample rows
they make (the dtype of the state mode's ``sample`` frame, so every consumer
reads both modes alike) with the filter's states from the host's replay of
the firmware's own C (:class:`accelnav.link.replay.Replay`).

The rules, frame by frame (:meth:`CompactStream.order`; vectorised when a
batch holds nothing but the next frames in order, which is the common case):

* The stream is a run of samples with 32-bit indices. A block whose first
  index is before the end of the run so far is a repeat or an older frame:
  dropped and counted in ``duplicates`` (its samples), never delivered twice.
  A block or checkpoint after the end of the run means frames were lost: the
  samples in between are counted in ``lost``, gaps of any length, unless the
  frame is flagged ``resume`` (the firmware paused: a stop, a mode change).
* A checkpoint at the end of the run is held against the replay (bit for bit:
  a mismatch is counted in ``mismatches`` and the rows since the stretch
  began are flagged ``mismatch``) and the replay goes on from the
  checkpoint's state; a sample whose step verdict (input taken or refused)
  differs from the code the firmware sent counts as a mismatch too. After a gap the replay starts again at the next
  checkpoint: the samples received in between have no state and are counted
  in ``lost`` as well, so ``lost`` is exactly the samples of the run that
  were not delivered.
* Every block and checkpoint carries its run id (the board's boot id plus one
  per reset command). A frame of another run starts a new run (a reset, a
  reboot); a frame of a run before it is a repeat (re-sent power-on frames),
  dropped and counted. Within a run a checkpoint before the end is a repeat
  (``checkpoint_repeats``), whatever its flags.
* The stream's first frame, a frame that opens a new run, or one that jumps
  more than ``4 x checkpoint_samples`` ahead is taken only when one of the
  next frames agrees with it (same run, a little after it) before one agrees
  with the run so far; otherwise it is damage (``damaged``, the decoder's
  ``bad_frames``), not the new truth. The last frame of a batch waits for the
  next batch to decide; at the end of the stream it is damage.
* A pause (frames flagged ``resume`` after a gap) counts nothing lost by
  itself; the run's checkpoints say where the firmware paused (``paused_at``),
  so the samples it sent before the pause that never arrived count in
  ``lost``. Rows held before a pause go out before any state-mode row that
  followed it (:meth:`CompactStream.release_before`): the index of the rows
  delivered only grows within a run, however the bytes were cut.

A checkpoint the decoder refused never reaches this class: a damaged frame, or
one whose contents no firmware sends (an axis that does not exist, a
gain-schedule row index outside the table:
:meth:`accelnav.link.manifest.Manifest.checkpoints_sane`). It counts in
``bad_frames`` and the stream goes on as if it had been lost.

Without a replay (no model text: a log recorded with ``--manifest``), the
ordering and the counts are the same but no row is delivered; the samples
are counted in ``unreplayed``.
"""

from __future__ import annotations

import numpy as np


def concat_records(parts: list, dtype) -> np.ndarray:
    """np.concatenate of structured arrays of one dtype, as bytes (numpy copies records field by field:
    several times slower)."""
    n = dtype.itemsize
    raw = [np.ascontiguousarray(p).view(np.uint8).reshape(-1, n) for p in parts if len(p)]
    if not raw:
        return np.zeros(0, dtype)
    return np.concatenate(raw).view(dtype).ravel()


LOOKAHEAD = 8  # frames after a doubtful one that may confirm or refute it
CARRY, NONE = -2, -1  # a stretch starts from the carried state, a checkpoint (its id), or nothing
THREAD_MIN = 20_000  # samples in a batch from which the axes' replays run on threads


class CompactStream:
    def __init__(self, man, replay=None):
        self.man = man
        self.replay = replay
        self.axes = list(man.axes)
        self.B = int(man.data["block_samples"])
        self.state_bytes = [int(n) for n in man.data["state_bytes"]]
        self.window = 4 * int(man.data["checkpoint_samples"])
        self.R = 1 << man.flags["resume"]
        self.X = 1 << man.flags["reset"]
        self.REPLAYED = 1 << man.flags["replayed"]
        self.MISMATCH = 1 << man.flags["mismatch"]
        self.raw = man.raw_fields()
        self.sample_dtype = man.dtypes["sample"]
        self.end: int | None = None  # the index after the run's last sample so far
        self.carry: list[bytes | None] = [None] * len(self.axes)  # replay state at `end`, per axis
        self.run: int | None = None  # the run id (boot id + resets) of the run being decoded
        self.past_runs: set[int] = set()  # runs before it: their frames, re-sent, are repeats
        self.pause_from: int | None = None  # end of the run at a pause, until a checkpoint's paused_at says more
        self.known_pause = -1  # the latest paused_at the run's checkpoints said so far
        self.blind_gap: tuple[int, int] | None = None  # (end, index after) of the last unflagged gap, until a
        # checkpoint says whether a pause fell inside it (:meth:`_Walk._unseen_pause`)
        self.pending = None  # (kind, record): a frame waiting for the next batch to confirm it
        self.defer = None
        self.seg_len = [int(man.frames[n]["size"]) + 5 for n in ("block", "checkpoint")]  # bytes, no delimiter
        self.damaged_bytes = 0
        self.damaged = 0  # CRC-valid frames refused: a run or an index no frame after them agreed with
        self.last_ck: list[int | None] = [None] * len(self.axes)  # index of the axis' last checkpoint taken
        # rows wait until the checkpoint closing their stretch came (so that a mismatch flags them all):
        # samples are numbered g = 0, 1, ... as accepted; open_from[j]: g where axis j's open stretch began
        self.g = 0
        self.open_from = [0] * len(self.axes)
        self.held = (np.zeros(0, self.sample_dtype), np.zeros(0, np.int64))  # rows, their g
        self.held_pos = np.zeros(0, np.int64)  # their stream positions (-1: an earlier batch)
        self.lost = self.duplicates = self.mismatches = self.checkpoints = 0
        self.checkpoint_repeats = self.unreplayed = 0
        self._pool = None  # replay threads, made on the first large batch

    # ------------------------------------------------------------------
    def order(
        self,
        kinds,
        ids,
        b_index,
        b_n,
        b_flags,
        c_index,
        c_flags,
        c_axis,
        c_state,
        runs=None,
        b_run=None,
        c_run=None,
        c_paused=None,
    ):
        """The per-frame rule over frames in stream order (``kinds`` 0 block, 1 checkpoint; ``ids`` into the
        block or checkpoint arrays): (accepted block ids, break positions, per axis [[position, ck id, verify,
        sync]]): a checkpoint verifies the stretch ending at its position unless a break came first there, and
        the replay starts from it unless a break follows it there (its state is then the one before a gap).
        ``runs`` (from :meth:`feed`): (run_end, prev_end, nbefore, run ids): frames k .. run_end[k] - 1 each
        continue the one before them in the stream (no flag, no repeated checkpoint, the same run id),
        prev_end[k] being where the frame before k left the index; reached with ``end == prev_end[k]`` in
        that run, such a run is taken whole. ``b_run``, ``c_run``: the frames' run ids; ``c_paused``: the
        checkpoints' ``paused_at``. A frame that opens a new run or jumps more than ``window`` samples ahead
        is taken only once the next frame agrees with it (else it is damage, counted in ``damaged``); the
        batch's last frame waits in ``self.defer`` for the next batch."""
        f = _Frames(kinds, ids, b_index, b_n, b_flags, c_index, c_flags, c_axis, b_run, c_run, c_paused)
        w = _Walk(self, f, runs)
        self.defer = None
        w.walk()
        self.end = w.end
        return w.acc, w.breaks, w.events

    # ------------------------------------------------------------------
    def feed(self, blocks: np.ndarray, bpos: np.ndarray, cks: np.ndarray, cpos: np.ndarray, more: bool = False):
        """Accepted block and checkpoint frames of one batch with their stream positions: (rows, row positions).
        ``more``: frames of the batch fed before too (split at sample frames): the held rows keep positions."""
        if not more:
            self.held_pos = np.full(len(self.held_pos), -1, np.int64)  # held rows: from before this batch now
        if self.pending is not None:  # the frame the last batch left undecided goes first (before position 0)
            kind, rec = self.pending
            self.pending = None
            if kind == 0:
                blocks, bpos = np.concatenate([rec, blocks]), np.r_[-1, bpos].astype(np.int64)
            else:
                cks, cpos = np.concatenate([rec, cks]), np.r_[-1, cpos].astype(np.int64)
        nb, nc = len(blocks), len(cks)
        empty = np.zeros(0, self.sample_dtype), np.zeros(0, np.int64)
        if nb + nc == 0:
            return empty
        b_run = blocks["run"].astype(np.int64)
        c_run = cks["run"].astype(np.int64)
        b_index = blocks["index"].astype(np.int64)
        b_n = blocks["n"].astype(np.int64)
        b_flags = blocks["flags"].astype(np.int64)
        c_index = cks["index"].astype(np.int64)
        c_flags = cks["flags"].astype(np.int64)
        c_axis = cks["axis"].astype(np.int64)
        kinds = np.r_[np.zeros(nb, np.int8), np.ones(nc, np.int8)]
        ids = np.r_[np.arange(nb), np.arange(nc)]
        o = np.argsort(np.r_[bpos, cpos], kind="stable")
        kinds, ids = kinds[o], ids[o]
        # the common case: every frame the next one of the run, none flagged resume or reset
        isb = kinds == 0
        n_sel = np.zeros(len(kinds), np.int64)
        n_sel[isb] = b_n[ids[isb]]
        nbefore = np.cumsum(n_sel) - n_sel
        if self.end is not None:
            idx = np.empty(len(kinds), np.int64)
            fl = np.empty(len(kinds), np.int64)
            idx[isb], idx[~isb] = b_index[ids[isb]], c_index[ids[~isb]]
            fl[isb], fl[~isb] = b_flags[ids[isb]], c_flags[ids[~isb]]
            regular = bool(np.all(idx == self.end + nbefore) and not np.any(fl & (self.R | self.X)))
            regular = regular and bool(np.all(b_run == self.run) and np.all(c_run == self.run))
            regular = regular and self.blind_gap is None  # a checkpoint may still tell of a pause inside it
            if regular and nc:  # and no checkpoint twice (the rule counts a repeat)
                ax_o, idx_o = c_axis[ids[~isb]], c_index[ids[~isb]]
                for j in range(len(self.axes)):
                    seen = idx_o[ax_o == j]
                    if len(seen) and (np.any(np.diff(seen) == 0) or seen[0] == self.last_ck[j]):
                        regular = False
        else:
            regular = False
        if regular:
            acc = ids[kinds == 0]
            breaks: list[int] = []
            events = [[] for _ in self.axes]
            ck_at = nbefore[kinds == 1]
            ck_ids = ids[kinds == 1]
            for p, i in zip(ck_at.tolist(), ck_ids.tolist(), strict=True):
                events[int(c_axis[i])].append([p, i, True, True])
                self.last_ck[int(c_axis[i])] = int(c_index[i])
            if nc:
                self.known_pause = max(self.known_pause, int(cks["paused_at"].max()))
            self.end = self.end + int(b_n.sum())
        else:
            acc, breaks, events = self.order(
                kinds.tolist(),
                ids.tolist(),
                b_index.tolist(),
                b_n.tolist(),
                b_flags.tolist(),
                c_index.tolist(),
                c_flags.tolist(),
                c_axis.tolist(),
                cks["state"],
                self._runs(kinds, ids, isb, n_sel, b_index, b_n, b_flags, c_index, c_flags, c_axis, b_run, c_run),
                b_run.tolist(),
                c_run.tolist(),
                cks["paused_at"].astype(np.int64).tolist(),
            )
            acc = np.asarray(acc, np.int64)
            if self.defer is not None:
                kind, i = self.defer
                self.pending = (kind, (blocks if kind == 0 else cks)[i : i + 1].copy())
        return self._rows(blocks[acc], bpos[acc], breaks, events, cks)

    def state_frames(self, index: int) -> None:
        """Sample frames of the state mode reached ``index`` (the last one's) since the frames fed before: the
        run went on there. Its samples are the state mode's to count, not a gap of the compact stream, and
        the replay's carried state is stale (a break)."""
        if self.pending is not None or (self.end is not None and index < self.end):
            return
        if self.end is None and self.run is not None:
            return  # a new run's first frames were judged damage: its start is not known
        self.end = index + 1  # (the stream's first frames: the run is the next compact frame's)
        self.carry = [None] * len(self.axes)
        self.pause_from = self.blind_gap = None

    def _runs(self, kinds, ids, isb, n_sel, b_index, b_n, b_flags, c_index, c_flags, c_axis, b_run, c_run):
        """For :meth:`order`: which frames continue the one before them in the stream (vectorised)."""
        K = len(kinds)
        idx = np.empty(K, np.int64)
        fl = np.empty(K, np.int64)
        run = np.empty(K, np.int64)
        run[isb], run[~isb] = b_run[ids[isb]], c_run[ids[~isb]]
        idx[isb], idx[~isb] = b_index[ids[isb]], c_index[ids[~isb]]
        fl[isb], fl[~isb] = b_flags[ids[isb]], c_flags[ids[~isb]]
        # where the frame before left the index: the end of the last block before it in the stream
        bend = np.where(isb, idx + n_sel, -1)
        last = np.maximum.accumulate(np.where(isb, np.arange(K), -1))
        prev = np.r_[-1, last[:-1]]
        prev_end = np.where(prev >= 0, bend[np.maximum(prev, 0)], -2 if self.end is None else self.end)
        cont = (idx == prev_end) & ((fl & (self.R | self.X)) == 0)
        cont &= run == np.r_[-1 if self.run is None else self.run, run[:-1]]  # the run of the frame before
        ax = np.where(isb, -1, c_axis[np.where(isb, 0, ids)] if len(c_axis) else -1)
        for j in range(len(self.axes)):  # a checkpoint again right after itself is no continuation
            at = np.flatnonzero(ax == j)
            if len(at):
                before = np.r_[-1 if self.last_ck[j] is None else self.last_ck[j], idx[at[:-1]]]
                cont[at[idx[at] == before]] = False
        # run_end[k]: the first frame at or after k + 1 that does not continue (k itself may start a run)
        stops = np.r_[np.flatnonzero(~cont), K]
        nxt = stops[np.searchsorted(stops, np.arange(K) + 1)]
        run_end = np.where(cont, nxt, np.arange(K))
        nbefore = np.r_[0, np.cumsum(n_sel)]
        return run_end.tolist(), prev_end.tolist(), nbefore.tolist(), run.tolist()

    # ------------------------------------------------------------------
    def _rows(self, blk, bpos, breaks, events, cks):
        B = self.B
        n_ax = len(self.axes)
        ns = blk["n"].astype(np.int64)
        N = int(ns.sum())
        if N == len(ns) * B:  # every block full: the slots in order without a gather

            def take(a):
                return a.reshape(N, *a.shape[2:])

        else:
            mask = np.arange(B)[None, :] < ns[:, None]

            def take(a):
                return a[mask]

        aflags = take(blk["aflags"])
        codes = [((aflags >> (2 * j)) & 3).astype(np.uint8) for j in range(n_ax)]
        raw = {(j, k): take(blk[f"{ax}.{k}"]) for j, ax in enumerate(self.axes) for k in self.raw}
        held_rows, held_g = self.held
        h = len(held_rows)
        whole = np.empty(h + N, self.sample_dtype)  # the held rows first: no copy of the batch's rows later
        whole[:h] = held_rows
        rows = whole[h:]
        breakset = set(breaks)
        valid = np.ones(N, bool)
        mism = np.zeros(N, bool)
        g0 = self.g
        held_mism = np.zeros(h, bool)
        ck_states = cks["state"]

        def flag(seg):
            """A stretch the replay disagreed on: its rows in this batch, and the held ones it began with."""
            mism[seg[0] : seg[1]] = True
            held_mism[held_g >= seg[3]] = True

        plans = [self._plan(j, N, breakset, events[j], valid, g0) for j in range(n_ax)]
        if self.replay is None:
            valid[:] = False
        jobs = []
        if self.replay is not None:
            for j, pl in enumerate(plans):
                if pl["live"]:
                    in1 = raw[(j, self.raw[0])]
                    in2 = raw[(j, self.raw[1])] if len(self.raw) > 1 else None
                    jobs.append((j, *self._starts(j, pl, ck_states), codes[j], in1, in2, rows))
        results = self._replay_all(jobs, N)
        for j, pl in enumerate(plans):
            self._verify(j, pl, results.get(j), ck_states, flag, held_mism, held_g)
        if self.replay is None:
            self.unreplayed += N
        else:
            self.lost += int(np.count_nonzero(~valid))
        self.g = g0 + N
        if self.replay is not None:
            self._assemble(rows, blk, mism)
        if held_mism.any():
            whole["flags"][:h] |= np.where(held_mism, self.MISMATCH, 0).astype(whole["flags"].dtype)
        # the held rows came before these frames (position -1 when from an earlier batch)
        rpos = np.r_[self.held_pos[:h], np.repeat(bpos, ns)]
        g = np.r_[held_g, g0 + np.arange(N)]
        if not valid.all():  # drop the runs of rows without a state: whole runs copied (a record gather is slow)
            keep = np.r_[np.ones(h, bool), valid]
            edges = np.flatnonzero(np.diff(np.r_[0, keep.view(np.int8), 0]))
            runs = list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
            whole = concat_records([whole[a:b] for a, b in runs], whole.dtype)
            rpos, g = rpos[keep], g[keep]
        cut = int(np.searchsorted(g, min(self.open_from)))  # g increases: deliver what no open stretch holds
        self.held = (whole[cut:].copy(), g[cut:])
        self.held_pos = rpos[cut:]
        return whole[:cut], rpos[:cut]

    def _starts(self, j: int, pl: dict, ck_states: np.ndarray):
        """Axis j's replay stretches: (start, length, initial state) of each live one, the state from its
        checkpoint or the carried one."""
        segs, live, nbj = pl["segs"], pl["live"], self.state_bytes[j]
        start = np.array([segs[k][0] for k in live], np.int64)
        length = np.array([segs[k][1] - segs[k][0] for k in live], np.int64)
        srcs = np.array([segs[k][2] for k in live], np.int64)
        init = np.empty((len(live), nbj), np.uint8)
        from_ck = srcs >= 0
        init[from_ck] = ck_states[srcs[from_ck], :nbj]
        if not from_ck.all():
            init[~from_ck] = np.frombuffer(pl["carry"], np.uint8)
        return start, length, init

    def _verify(self, j: int, pl: dict, result, ck_states: np.ndarray, flag, held_mism, held_g) -> None:
        """Axis j after its replay (``result``: final states and step verdicts, or None): the checkpoints held
        against the final states, disagreements flagged (``flag``, ``held_mism``), the carried state kept."""
        nbj = self.state_bytes[j]
        segs, live, checks, src, carry = pl["segs"], pl["live"], pl["checks"], pl["src"], pl["carry"]
        fin = np.zeros((max(len(segs), 1), nbj), np.uint8)  # a row even without a stretch (N == 0)
        has_fin = np.zeros(len(fin), bool)
        if result is not None:
            f, nbad = result
            fin[live] = f
            has_fin[live] = True
            for m in np.flatnonzero(nbad).tolist():
                self.mismatches += int(nbad[m])
                flag(segs[live[m]])
        if checks:
            ks = np.array([k for k, _ in checks], np.int64)
            ids = np.array([i for _, i in checks], np.int64)
            ok = np.where(ks >= 0, has_fin[np.maximum(ks, 0)], True)
            got = fin[np.maximum(ks, 0)]
            if (ks < 0).any():
                got[ks < 0] = np.frombuffer(carry, np.uint8)
            same = (got == ck_states[ids, :nbj]).all(axis=1)
            self.checkpoints += int(np.count_nonzero(ok & same))
            for k in ks[ok & ~same].tolist():
                self.mismatches += 1
                if k >= 0:
                    flag(segs[k])
                else:  # the carried stretch: only held rows
                    held_mism[held_g >= pl["stale_from"]] = True
        if src == "continue":
            self.carry[j] = fin[-1].tobytes() if segs and has_fin[-1] else None
        elif src == CARRY:
            pass  # no sample and no checkpoint in this batch: the carried state stays
        else:
            self.carry[j] = None if src == NONE else ck_states[src, :nbj].tobytes()

    def _plan(self, j: int, N: int, breakset: set, events: list, valid: np.ndarray, g0: int) -> dict:
        """Axis j's stretches in a batch of N samples: where the replay starts from the carried state, from a
        checkpoint or not at all (the samples without a state are cleared in ``valid``), and which
        checkpoints verify which stretch's final state."""
        ev_at: dict[int, list[int]] = {}  # checkpoints verifying the stretch that ends here
        sync_at: dict[int, int] = {}  # the checkpoint the replay starts from here
        for p, i, verify, sync in events:
            if verify:
                ev_at.setdefault(p, []).append(i)
            if sync:
                sync_at[p] = i
        points = sorted(breakset | set(ev_at) | set(sync_at) | {0, N})
        carry = self.carry[j]
        src = CARRY if (carry is not None and 0 not in breakset) else NONE
        opened = self.open_from[j] if src == CARRY else g0  # g where the open stretch began
        checks = []  # (stretch number or -1 for the carried state, checkpoint id)
        segs = []  # (start, end, source, g where the stretch began)
        if carry is not None and 0 in ev_at:  # no break before them: they close the carried stretch
            checks += [(-1, i) for i in ev_at[0]]
        if 0 in sync_at:
            src, opened = sync_at[0], g0
        for a, b in zip(points[:-1], points[1:], strict=True):
            segs.append((a, b, src, opened))
            checks += [(len(segs) - 1, i) for i in ev_at.get(b, [])]
            if b in sync_at:
                src, opened = sync_at[b], g0 + b
            elif b in breakset:
                src, opened = NONE, g0 + b
            else:
                src = "continue"  # only at b == N: the last stretch's final state is carried
        stale_from = self.open_from[j]
        self.open_from[j] = opened
        for sg in segs:
            if sg[2] == NONE:
                valid[sg[0] : sg[1]] = False
        live = [k for k, sg in enumerate(segs) if sg[2] != NONE]
        return {"segs": segs, "live": live, "checks": checks, "src": src, "carry": carry, "stale_from": stale_from}

    def _replay_all(self, jobs: list, n: int) -> dict:
        """{axis: (final states, verdict mismatches)} of the replay jobs over a batch of n samples; the axes'
        replays run on threads (the C releases the GIL) when the batch is large enough to pay for it."""
        if len(jobs) > 1 and n >= THREAD_MIN:
            if self._pool is None:
                from concurrent.futures import ThreadPoolExecutor

                self._pool = ThreadPoolExecutor(len(self.axes), thread_name_prefix="acn-replay")
            futs = {job[0]: self._pool.submit(self.replay.run, *job) for job in jobs}
            return {j: f.result() for j, f in futs.items()}
        return {job[0]: self.replay.run(*job) for job in jobs}

    def release(self) -> np.ndarray:
        """End of the stream: the rows after the last checkpoint (replayed, never verified). A frame still
        waiting for one to confirm it never got one: damage."""
        if self.pending is not None:
            self.damaged += 1
            self.damaged_bytes += self.seg_len[self.pending[0]]
            self.pending = None
        rows = self.held[0]
        self.held = (np.zeros(0, self.sample_dtype), np.zeros(0, np.int64))
        self.held_pos = np.zeros(0, np.int64)
        self.open_from = [self.g] * len(self.axes)
        return rows

    def release_before(self, pos: int) -> tuple[np.ndarray, np.ndarray]:
        """The held rows of frames before stream position ``pos`` of the last batch (earlier batches: all),
        with their positions: the state mode's sample frames after them must not overtake them (a pause
        whose checkpoints were lost leaves them waiting for a checkpoint that will not come). They go out
        replayed and unverified, as at the end of a stream."""
        k = int(np.searchsorted(self.held_pos, pos))
        if k == 0:
            return np.zeros(0, self.sample_dtype), np.zeros(0, np.int64)
        rows, g = self.held
        out, out_pos = rows[:k], self.held_pos[:k]
        self.held = (rows[k:].copy(), g[k:])
        self.held_pos = self.held_pos[k:]
        self.open_from = [max(o, int(g[k - 1]) + 1) for o in self.open_from]
        return out, out_pos

    def _assemble(self, rows, blk, mism) -> None:
        """Every field of the rows but the states (the replay wrote those), through the replay's C fill."""
        rx = self.R | self.X
        self.replay.fill(blk, rows, self.man.code_flags(), ~rx & 0xFFFF, self.REPLAYED, rx)
        if mism.any():
            rows["flags"] |= np.where(mism, self.MISMATCH, 0).astype(rows["flags"].dtype)


class _Frames:
    """The frames :meth:`CompactStream.order` walks, as lists (one ``kinds``/``ids`` entry per frame in stream
    order; the other lists per block or per checkpoint)."""

    def __init__(self, kinds, ids, b_index, b_n, b_flags, c_index, c_flags, c_axis, b_run, c_run, c_paused):
        self.kinds, self.ids = kinds, ids
        self.b_index, self.b_n, self.b_flags = b_index, b_n, b_flags
        self.c_index, self.c_flags, self.c_axis = c_index, c_flags, c_axis
        self.b_run = b_run if b_run is not None else [0] * len(b_index)
        self.c_run = c_run if c_run is not None else [0] * len(c_index)
        self.c_paused = c_paused if c_paused is not None else [None] * len(c_index)

    def where(self, q: int) -> tuple[int, int, int]:
        """(run id, index, index after it) of frame q."""
        j = self.ids[q]
        if self.kinds[q] == 0:
            return self.b_run[j], self.b_index[j], self.b_index[j] + self.b_n[j]
        return self.c_run[j], self.c_index[j], self.c_index[j]


class _Walk:
    """One pass of :meth:`CompactStream.order`: the index reached (``end``), the sample position in the
    batch (``pos``), the accepted blocks, the breaks and the per-axis checkpoint events so far. The
    stream's own state and counts stay on the :class:`CompactStream` (``cs``)."""

    def __init__(self, cs: CompactStream, f: _Frames, runs):
        self.cs, self.f, self.runs = cs, f, runs
        self.end = cs.end
        self.pos = 0
        self.acc: list[int] = []
        self.breaks: list[int] = []
        self.events: list[list[list]] = [[] for _ in cs.axes]

    def walk(self) -> None:
        cs, f, runs = self.cs, self.f, self.runs
        k, K = 0, len(f.kinds)
        while k < K:
            # frames k .. that continue the one before, from where the stream is (a checkpoint right after a
            # break goes by the rule)
            if (
                runs is not None
                and self.end is not None
                and runs[0][k] > k
                and runs[1][k] == self.end
                and runs[3][k] == cs.run
                and not self._broken_here()
            ):
                r = self._bulk(k)
                if r is not None:
                    k = r
                    continue
            if self._frame(k) is None:
                cs.defer = (f.kinds[k], f.ids[k])  # decided by the next frame, in the next batch
                break
            k += 1

    def _brk(self, p: int) -> None:
        """A break at position p: the checkpoints there no longer start the replay (a gap follows them)."""
        self.breaks.append(p)
        for ev in self.events:
            for e in ev[::-1]:
                if e[0] != p:
                    break
                e[3] = False

    def _broken_here(self) -> bool:
        return bool(self.breaks) and self.breaks[-1] == self.pos

    def _plausible(self, q: int) -> bool | None:
        """Frame q opens the stream or a new run, or jumps far ahead: decided by the first of the next
        frames that agrees with it (the same run, within a window after it: True) or with the run so far
        (False); None when no frame follows in this batch. Frames damaged beyond that: False."""
        cs, K = self.cs, len(self.f.kinds)
        r, idx, after = self.f.where(q)
        if q + 1 >= K:
            return None
        for q2 in range(q + 1, min(K, q + 1 + LOOKAHEAD)):
            r2, idx2, _ = self.f.where(q2)
            if r2 == r and idx <= idx2 <= after + cs.window:
                return True
            if self.end is not None and r2 == cs.run and idx2 <= self.end + cs.window:
                return False
        return False

    def _bulk(self, q: int) -> int | None:
        """Frames q .. r - 1 that each continue the one before (``runs``, checked by :meth:`walk`), taken as
        the rule would take them, in bulk: r, or None when frame q goes by the rule (a repeated checkpoint)."""
        cs, f, runs = self.cs, self.f, self.runs
        r, nb = runs[0][q], runs[2]
        for p in range(q, r):
            if f.kinds[p] == 1:
                j = f.ids[p]
                if cs.last_ck[f.c_axis[j]] == f.c_index[j]:
                    r = p  # the checkpoint just taken, again: the rule from here
                    break
                cs.last_ck[f.c_axis[j]] = f.c_index[j]
                self.events[f.c_axis[j]].append([self.pos + nb[p] - nb[q], j, True, True])
                if f.c_paused[j] is not None:
                    if cs.blind_gap is not None:
                        self._unseen_pause(f.c_index[j], f.c_paused[j])
                    cs.known_pause = max(cs.known_pause, int(f.c_paused[j]))
        if r <= q:
            return None
        blk = [f.ids[p] for p in range(q, r) if f.kinds[p] == 0]
        if blk:
            self.acc.extend(blk)
            self.pos += nb[r] - nb[q]
            self.end = f.b_index[blk[-1]] + f.b_n[blk[-1]]
        return r

    def _frame(self, q: int) -> bool | None:
        """The rule for frame q: True taken, False refused (a repeat or damage), None deferred."""
        cs, f = self.cs, self.f
        kind, i = f.kinds[q], f.ids[q]
        run, idx = (f.b_run[i], f.b_index[i]) if kind == 0 else (f.c_run[i], f.c_index[i])
        new_run = self.end is not None and cs.run is not None and run != cs.run
        if new_run and run in cs.past_runs:  # a frame of an earlier run, sent again
            if kind == 0:
                cs.duplicates += f.b_n[i]
            else:
                cs.checkpoint_repeats += 1
            return False
        if new_run or self.end is None or idx > self.end + cs.window:
            ok = self._plausible(q)
            if ok is None:
                return None
            if not ok:
                cs.damaged += 1  # a CRC-valid frame no firmware sent here: not the new truth
                cs.damaged_bytes += cs.seg_len[kind]
                return False
        if new_run:
            cs.past_runs = cs.past_runs | {cs.run}
            if len(cs.past_runs) > 64:
                cs.past_runs = set(sorted(cs.past_runs)[-64:])
            cs.run = run
            cs.pause_from = cs.blind_gap = None
            cs.known_pause = -1
            self._brk(self.pos)
            self.end = None  # the new run's first frame: no gap counted against the old run
        if self.end is None or cs.run is None:
            cs.run = run
        return self._block(i, idx) if kind == 0 else self._checkpoint(i, idx)

    def _gap(self, flags: int, idx: int) -> None:
        """The stream jumps from ``end`` to ``idx``: a pause (resume flag) or lost samples; a break."""
        if flags & self.cs.R:
            self.cs.pause_from = self.end  # a pause: paused_at will tell what was lost before it
        else:
            self.cs.lost += idx - self.end  # unless a checkpoint later shows a pause inside it
            self.cs.blind_gap = (self.end, idx)
        self._brk(self.pos)

    def _unseen_pause(self, idx: int, paused: int | None) -> None:
        """A checkpoint at ``idx`` after a gap without a resume flag (its frames lost): a ``paused_at`` the run
        had not said yet means the firmware paused inside the gap, and the samples from there to where it
        resumed were never sent, not lost. Where it resumed: the countdown puts the first checkpoint after a
        resume a whole number of ``checkpoint_samples`` after it, and the resume came before the gap's
        first frame (which carried no resume flag): the latest such index at or after the pause. When no
        index fits (a stop or flush came sooner after the resume), the gap stays counted as it was."""
        cs = self.cs
        gap, cs.blind_gap = cs.blind_gap, None
        if paused is None or gap is None or paused <= cs.known_pause:
            return
        start, after = gap
        if not start <= paused < after:
            return
        C = cs.window // 4
        resumed = idx - -(-(idx - (after - 1)) // C) * C  # the latest idx - k C at or before after - 1
        if resumed >= paused:
            cs.lost -= resumed - paused

    def _block(self, i: int, idx: int) -> bool:
        n = self.f.b_n[i]
        if self.end is None:
            self._brk(self.pos)  # the first frame seen, or a new run whose checkpoints were lost
        elif idx < self.end:
            self.cs.duplicates += n
            return False
        elif idx > self.end:
            self._gap(self.f.b_flags[i], idx)
        self.acc.append(i)
        self.pos += n
        self.end = idx + n
        return True

    def _checkpoint(self, i: int, idx: int) -> bool:
        cs, f, end = self.cs, self.f, self.end
        ax, fl = f.c_axis[i], f.c_flags[i]
        if end is not None and idx < end:
            cs.checkpoint_repeats += 1  # an older checkpoint of this run
            return False
        if end is not None and idx == end and cs.last_ck[ax] == idx and not fl & cs.X:
            cs.checkpoint_repeats += 1  # the one just taken, again
            return False
        if end is None or idx > end:
            if end is None:
                self._brk(self.pos)
            else:
                self._gap(fl, idx)
            self.end = idx
        if cs.pause_from is not None and f.c_paused[i] is not None:
            # samples the firmware sent before the pause that never arrived
            cs.lost += max(0, min(int(f.c_paused[i]), idx) - cs.pause_from)
            cs.pause_from = None
        if cs.blind_gap is not None:
            self._unseen_pause(idx, f.c_paused[i])
        if f.c_paused[i] is not None:
            cs.known_pause = max(cs.known_pause, int(f.c_paused[i]))
        cs.last_ck[ax] = idx
        self.events[ax].append([self.pos, i, not self._broken_here(), True])
        return True
