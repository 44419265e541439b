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
* A checkpoint flagged ``reset`` before the end of the run starts a new run
  (a reset command, a reboot), unless it is byte for byte the checkpoint that
  opened the current run and less than ``4 x checkpoint_samples`` samples
  back (then it is a repeat). A repeated older checkpoint is ignored
  (``checkpoint_repeats``).

A checkpoint the decoder refused never reaches this class: a damaged frame, or
one whose contents no firmware sends (an axis that does not exist, a
gain-schedule row index outside the table:
:meth:`accelnav.link.telemetry.Manifest.checkpoints_sane`). It counts in
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
        self.opener: list[tuple[int, bytes] | None] = [None] * len(self.axes)
        self.last_ck: list[int | None] = [None] * len(self.axes)  # index of the axis' last checkpoint taken
        # rows wait until the checkpoint closing their stretch came (so that a mismatch flags them all):
        # samples are numbered g = 0, 1, ... as accepted; open_from[j]: g where axis j's open stretch began
        self.g = 0
        self.open_from = [0] * len(self.axes)
        self.held = (np.zeros(0, self.sample_dtype), np.zeros(0, np.int64))  # rows, their g
        self.lost = self.duplicates = self.mismatches = self.checkpoints = 0
        self.checkpoint_repeats = self.unreplayed = 0
        self._pool = None  # replay threads, made on the first large batch

    # ------------------------------------------------------------------
    def order(self, kinds, ids, b_index, b_n, b_flags, c_index, c_flags, c_axis, c_state, runs=None):
        """The per-frame rule over frames in stream order (``kinds`` 0 block, 1 checkpoint; ``ids`` into the
        block or checkpoint arrays): (accepted block ids, break positions, per axis [[position, ck id, verify,
        sync]]): a checkpoint verifies the stretch ending at its position unless a break came first there, and
        the replay starts from it unless a break follows it there (its state is then the one before a gap).
        ``runs`` (from :meth:`feed`): (run_end, prev_end, nbefore): frames k .. run_end[k] - 1 each continue
        the one before them in the stream (no flag, no repeated checkpoint), prev_end[k] being where the
        frame before k left the index; reached with ``end == prev_end[k]``, such a run is taken whole."""
        end = self.end
        acc, breaks = [], []
        events: list[list[list]] = [[] for _ in self.axes]
        pos = 0
        R, X = self.R, self.X

        def brk(p):
            breaks.append(p)
            for ev in events:
                for e in ev[::-1]:
                    if e[0] != p:
                        break
                    e[3] = False

        k, K = 0, len(kinds)
        while k < K:
            kind, i = kinds[k], ids[k]
            k += 1
            bulk = runs is not None and end is not None and runs[0][k - 1] > k - 1 and runs[1][k - 1] == end
            if bulk and not (breaks and breaks[-1] == pos):  # (a checkpoint right after a break: the rule)
                r = runs[0][k - 1]  # frames k - 1 .. r - 1 follow on: accepted as the rule would, in bulk
                nb = runs[2]
                for q in range(k - 1, r):
                    if kinds[q] == 1:
                        j = ids[q]
                        if self.last_ck[c_axis[j]] == c_index[j]:
                            r = q  # the checkpoint just taken, again: the rule from here
                            break
                        self.last_ck[c_axis[j]] = c_index[j]
                        events[c_axis[j]].append([pos + nb[q] - nb[k - 1], j, True, True])
                if r > k - 1:
                    blk = [ids[q] for q in range(k - 1, r) if kinds[q] == 0]
                    if blk:
                        acc.extend(blk)
                        pos += nb[r] - nb[k - 1]
                        end = b_index[blk[-1]] + b_n[blk[-1]]
                    k = r
                    continue
            if kind == 0:
                idx, n, fl = b_index[i], b_n[i], b_flags[i]
                if end is None or (fl & X and idx < end and end - idx > self.window):
                    brk(pos)  # the first frame seen, or a reset whose checkpoints were lost
                elif idx < end:
                    self.duplicates += n
                    continue
                elif idx > end:
                    if not fl & R:
                        self.lost += idx - end
                    brk(pos)
                acc.append(i)
                pos += n
                end = idx + n
                continue
            idx, fl, ax = c_index[i], c_flags[i], c_axis[i]
            if end is not None and idx < end:
                st = bytes(c_state[i])
                op = self.opener[ax]
                if fl & X and not (op is not None and op == (idx, st) and end - idx <= self.window):
                    brk(pos)  # a new run: a reset or a reboot
                    end = idx
                    self.opener[ax] = (idx, st)
                    self.last_ck[ax] = idx
                    events[ax].append([pos, i, False, True])
                else:
                    self.checkpoint_repeats += 1
                continue
            if end is not None and idx == end and self.last_ck[ax] == idx and not fl & X:
                self.checkpoint_repeats += 1  # the one just taken, again
                continue
            if end is None or idx > end:
                if end is not None and not fl & R:
                    self.lost += idx - end
                brk(pos)
                end = idx
            if fl & (R | X):
                self.opener[ax] = (idx, bytes(c_state[i]))
            self.last_ck[ax] = idx
            events[ax].append([pos, i, not (breaks and breaks[-1] == pos), True])
        self.end = end
        return acc, breaks, events

    # ------------------------------------------------------------------
    def feed(self, blocks: np.ndarray, bpos: np.ndarray, cks: np.ndarray, cpos: np.ndarray):
        """Accepted block and checkpoint frames of one batch with their stream positions: (rows, row positions)."""
        nb, nc = len(blocks), len(cks)
        empty = np.zeros(0, self.sample_dtype), np.zeros(0, np.int64)
        if nb + nc == 0:
            return empty
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
                self._runs(kinds, ids, isb, n_sel, b_index, b_n, b_flags, c_index, c_flags, c_axis),
            )
            acc = np.asarray(acc, np.int64)
        return self._rows(blocks[acc], bpos[acc], breaks, events, cks)

    def _runs(self, kinds, ids, isb, n_sel, b_index, b_n, b_flags, c_index, c_flags, c_axis):
        """For :meth:`order`: which frames continue the one before them in the stream (vectorised)."""
        K = len(kinds)
        idx = np.empty(K, np.int64)
        fl = np.empty(K, np.int64)
        idx[isb], idx[~isb] = b_index[ids[isb]], c_index[ids[~isb]]
        fl[isb], fl[~isb] = b_flags[ids[isb]], c_flags[ids[~isb]]
        # where the frame before left the index: the end of the last block before it in the stream
        bend = np.where(isb, idx + n_sel, -1)
        last = np.maximum.accumulate(np.where(isb, np.arange(K), -1))
        prev = np.r_[-1, last[:-1]]
        prev_end = np.where(prev >= 0, bend[np.maximum(prev, 0)], -2 if self.end is None else self.end)
        cont = (idx == prev_end) & ((fl & (self.R | self.X)) == 0)
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
        return run_end.tolist(), prev_end.tolist(), nbefore.tolist()

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
        for j, pl in enumerate(plans):
            if self.replay is not None and pl["live"]:
                segs, live, nbj = pl["segs"], pl["live"], self.state_bytes[j]
                start = np.array([segs[k][0] for k in live], np.int64)
                length = np.array([segs[k][1] - segs[k][0] for k in live], np.int64)
                srcs = np.array([segs[k][2] for k in live], np.int64)
                init = np.empty((len(live), nbj), np.uint8)
                from_ck = srcs >= 0
                init[from_ck] = ck_states[srcs[from_ck], :nbj]
                if not from_ck.all():
                    init[~from_ck] = np.frombuffer(pl["carry"], np.uint8)
                in1 = raw[(j, self.raw[0])]
                in2 = raw[(j, self.raw[1])] if len(self.raw) > 1 else None
                jobs.append((j, start, length, init, codes[j], in1, in2, rows))
        results = self._replay_all(jobs, N)
        for j, pl in enumerate(plans):
            nbj = self.state_bytes[j]
            segs, live, checks, src, carry = pl["segs"], pl["live"], pl["checks"], pl["src"], pl["carry"]
            fin = np.zeros((max(len(segs), 1), nbj), np.uint8)  # a row even without a stretch (N == 0)
            has_fin = np.zeros(len(fin), bool)
            if j in results:
                f, nbad = results[j]
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
        if self.replay is None:
            self.unreplayed += N
        else:
            self.lost += int(np.count_nonzero(~valid))
        self.g = g0 + N
        if self.replay is not None:
            self._assemble(rows, blk, mism)
        if held_mism.any():
            whole["flags"][:h] |= np.where(held_mism, self.MISMATCH, 0).astype(whole["flags"].dtype)
        # the held rows came before this batch (position -1)
        rpos = np.r_[np.full(h, -1, np.int64), np.repeat(bpos, ns)]
        g = np.r_[held_g, g0 + np.arange(N)]
        if not valid.all():  # drop the runs of rows without a state: whole runs copied (a record gather is slow)
            keep = np.r_[np.ones(h, bool), valid]
            edges = np.flatnonzero(np.diff(np.r_[0, keep.view(np.int8), 0]))
            runs = list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))
            whole = concat_records([whole[a:b] for a, b in runs], whole.dtype)
            rpos, g = rpos[keep], g[keep]
        cut = int(np.searchsorted(g, min(self.open_from)))  # g increases: deliver what no open stretch holds
        self.held = (whole[cut:].copy(), g[cut:])
        return whole[:cut], rpos[:cut]

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
        """End of the stream: the rows after the last checkpoint (replayed, never verified)."""
        rows = self.held[0]
        self.held = (np.zeros(0, self.sample_dtype), np.zeros(0, np.int64))
        self.open_from = [self.g] * len(self.axes)
        return rows

    def _assemble(self, rows, blk, mism) -> None:
        """Every field of the rows but the states (the replay wrote those), through the replay's C fill."""
        rx = self.R | self.X
        self.replay.fill(blk, rows, self.man.code_flags(), ~rx & 0xFFFF, self.REPLAYED, rx)
        if mism.any():
            rows["flags"] |= np.where(mism, self.MISMATCH, 0).astype(rows["flags"].dtype)
