"""One engine for filter and smooth: read -> filter pass -> store -> backward pass -> write.

Every option goes through :func:`run`, which decides once, from the run's size against the memory
budget and from what was asked, how the passes are cut (:func:`plan`), and says why:

* **chunked** (:func:`accelnav.estimate.chunked.smooth_bounded`): the passes over chunks of the input,
  the store in memory or on disk, the output written in place into the run file. A run that fits the
  budget is one chunk. Plain runs, ``--filter-states``, fixes, given and detected rests, raw counts and
  truth columns of an input held in memory (echoed into the file) take this path at any length. Fixes
  and given rests (:class:`accelnav.estimate.zupt.RestSpans`) are placed on the run's clock a piece at a
  time and made into each chunk's aids as the forward pass reaches it (:class:`_AxisAids`), so that they
  need not the input held whole: only the rest decision (``--zupt auto``) reads it whole; the
  caller then writes ``--csv`` and ``--compress`` from the file a piece at a time
  (:mod:`accelnav.data.smoothing`). ``--plots`` over the budget keeps each series' min and max per bin of
  samples as the chunks go by (:class:`_RunEnvelope`, ``Outcome.envelope``): the figures draw that.
* **one chunk in memory** (:func:`smooth_arrays`, :func:`filter_arrays`: the same kernels' whole-array
  entry points): what needs every output sample in memory at once, namely the aids' consistency checks
  (the held-out fixes; the aids' NIS a chunked run writes too: fix_nis, zupt_nis), and a library call that
  wants arrays back. A run over the
  budget that asks for one of them is refused in one line before any work. ``--covariances`` within the
  budget is one chunk in memory; over it, it is chunked, its covariances written chunk by chunk. So is
  ``--tune``: over the budget its likelihood is summed chunk by chunk (:func:`accelnav.estimate.tune.tune_data`:
  every evaluation reads the input again, its aids made per chunk), the search in the memory of a chunk.

The stages are called from one place each: the rest decision (:func:`rest_stage`:
:func:`accelnav.estimate.zupt.decide_rests` with the run's fixes, then the review
:func:`accelnav.estimate.pipeline.disagreeing_rests`), the aids
(:func:`axis_extras`), the tune search, then the passes. A decision that needs a smoother pass over
the run is given ``smooth_pass`` (a callable running the bounded passes with trial aids and returning
per-axis smoothed velocities at chosen samples) so that it never holds the run's outputs whole.

Both paths agree to 1e-12 relative (tests/data/test_smoothing.py runs each option chunked at a small
budget against one chunk).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.estimate import chunked
from accelnav.estimate.checks import check_run
from accelnav.estimate.kf import Aids, Measurement
from accelnav.model.design import axis_design
from accelnav.model.load import Model
from accelnav.progress import note

# the recording's own keys; any other key of an input held in memory (raw counts, a simulation's truth) is
# echoed into the run file, and the outputs of an earlier stage (filt_*, smooth_*, aids) are recomputed
RECORDING_KEYS = ("t", "accel", "clipped", "axis_names", "format", "model_toml", "model_source")
STAGE_KEYS = ("filt_", "smooth_", "zupt", "fixes", "fix_nis")

_FULL = chunked.fastsmooth.UNPACK  # packed (N, 10) -> (N, 16) row-major
_DIAG = np.array([0, 4, 7, 9])
# bytes of store held in memory without a --memory-budget: with the chunk buffers (chunked.BUDGET) and the
# interpreter (~300 MB at 1e7 samples, measured) a run stays under 1 GB at any length; 2 x 2e7 samples of
# the lean store (16 B each) fit
STORE_MEMORY = 640 << 20


@dataclass(frozen=True)
class Rests:
    """Zero-velocity updates: ``detect`` (the rest decision on the acceleration, with ``params``), or a
    given (N,) or (N, n_axes) ``mask`` with optional per-sample ``sigma`` (NaN: ``params.sigma``)."""

    params: object = None  # zupt.ZuptParams; None: its defaults
    detect: bool = False
    mask: np.ndarray | None = None
    sigma: np.ndarray | None = None
    decided: Callable[[RestOutcome], None] | None = None  # called with the rest stage's outcome once decided
    candidates: np.ndarray | None = None  # (N,) bool, candidates to decide on (accelnav.level's rests); None: detected
    spans: object = None  # zupt.RestSpans: given rests as runs of samples (a rest file read on the run's clock)


@dataclass(frozen=True)
class Tune:
    """``--tune``: fit the noise figures first, in at most ``max_evaluations`` and ``max_seconds``."""

    max_evaluations: int = 300
    max_seconds: float = 60.0
    announce: Callable[[int, int, int], None] | None = None


@dataclass(frozen=True)
class Job:
    """What one filter or smooth is asked for (the command's flags as library values).

    ``stages``: the states written, ("filt",) for the filter, ("smooth",) or ("filt", "smooth");
    ``in_memory``: what else of the caller needs every sample in memory, by flag, so that the plan can refuse it
    over the budget; ``budget``: bytes (None: half the
    memory available); ``checks``: compute the aids' consistency checks (in memory) when the run fits."""

    stages: tuple[str, ...] = ("smooth",)
    fixes: Sequence[Sequence[Measurement]] | None = None
    rests: Rests | None = None
    tune: Tune | None = None
    covariances: bool = False
    in_memory: tuple[str, ...] = ()
    budget: int | None = None
    checks: bool = True
    warm_start: bool = False
    full: bool = False  # write every state at float64 and echo the input (else r, u and sds at float32)
    # --plots: within the budget the run is one chunk in memory (the figures draw every sample); over it the
    # outputs' min and max per bin of samples are kept as the chunks are written (Outcome.envelope)
    envelope: bool = False

    @property
    def aided(self) -> bool:
        return self.fixes is not None or self.rests is not None


@dataclass
class Source:
    """The input: ``n`` samples of ``axis_names``, rows read by ``read(s, e)`` (t, accel, clipped);
    ``arrays``: the whole run when it is held in memory (its other keys are echoed into the output)."""

    n: int
    axis_names: np.ndarray
    read: chunked.Reader
    arrays: dict | None = None
    label: str = "the run"
    t_ends: tuple[float, float] = (0.0, 0.0)
    streamed: str = ""  # the input's kind ("CSV", "NPZ") when it is read from a store or the file, not memory

    @classmethod
    def of(cls, arrays, label: str = "the run") -> Source:
        a = dict(arrays)
        t = np.asarray(a["t"])
        return cls(len(t), np.asarray(a["axis_names"]), chunked.array_reader(t, a["accel"], a["clipped"]), a, label,
                   (float(t[0]), float(t[-1])) if len(t) else (0.0, 0.0))  # fmt: skip

    def clock(self):
        """The run's time stamps read a piece at a time (accelnav.estimate.fixes.Clock): from memory, or through
        ``read`` (a stream's period is its grid's)."""
        from accelnav.estimate.fixes import Clock

        if self.arrays is not None:
            return Clock.of(self.arrays["t"])
        return Clock(self.n, lambda s, e: self.read(s, e)[0], getattr(self.read, "Ts", None) or None)

    def whole(self) -> dict:
        """The run in memory (read now when it was not)."""
        if self.arrays is None:
            t, accel, clipped = self.read(0, self.n)
            self.arrays = {"t": t, "axis_names": self.axis_names, "accel": accel, "clipped": clipped}
        return self.arrays

    def times_at(self, k) -> np.ndarray:
        """The run's t at samples ``k`` (any order): from memory, or read in one pass over the clock (a run read
        whole for the rest decision and dropped after it names its candidates' times this way)."""
        k = np.asarray(k, dtype=np.int64)
        if len(k) and (k.min() < 0 or k.max() >= self.n):  # the pass below would leave such a time unwritten
            raise IndexError(f"samples {k.min()}..{k.max()} outside the run's {self.n}")
        if self.arrays is not None:
            return np.asarray(self.arrays["t"])[k]
        out = np.empty(len(k))
        order = np.argsort(k, kind="stable")
        ks = k[order]
        for s, t in self.clock().pieces():
            lo, hi = np.searchsorted(ks, s), np.searchsorted(ks, s + len(t))
            out[order[lo:hi]] = t[ks[lo:hi] - s]
        return out

    def extra_keys(self) -> dict:
        """Keys of an input in memory that the run file keeps beside the outputs (raw counts, truth)."""
        if self.arrays is None:
            return {}
        return {k: v for k, v in self.arrays.items() if k not in RECORDING_KEYS and not k.startswith(STAGE_KEYS)}


@dataclass(frozen=True)
class Plan:
    """How a run is cut: ``whole`` (one chunk in memory, every output array returned) or chunked into
    ``chunk``-sample pieces written into the run file; ``why`` in words."""

    whole: bool
    chunk: int
    chunks: int
    budget: int
    why: str


@dataclass
class RestOutcome:
    """The rest stage's result: the (N,) mask of accepted rests (None: given as ``spans`` and not painted per
    sample, the chunked path) and, when detected, the decisions."""

    mask: np.ndarray | None
    sigma: np.ndarray | None
    params: object
    decisions: list = field(default_factory=list)
    gravity: list = field(default_factory=list)
    detected: bool = False
    review: object = None  # consistency.RestReview of the detected rests, or None
    reviewed: bool = True  # False: detected rests over the memory budget, not re-examined (said by the CLI)
    # the review's last smoothing, with exactly ``mask``'s rests (consistency.RestReview.smoothed): :func:`run`
    # takes it as the one-chunk output when nothing after the review changes the aids, else drops it at once
    smoothed: dict | None = field(default=None, repr=False)
    spans: object = None  # zupt.RestSpans of given rests
    _ends: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)  # candidate_ends, made once

    def runs(self, n_axes: int):
        """The rests as zupt.RestSpans (a mask's runs, made now)."""
        from accelnav.estimate.zupt import RestSpans

        return self.spans if self.spans is not None else RestSpans.of_mask(self.mask, self.sigma, n_axes)

    def candidate_ends(self) -> np.ndarray:
        """(K, 3) int64 [start, stop, accepted] per decision, made once (a Python loop over 1e4-1e5 of them; the
        decisions are final once the rest stage returns)."""
        if self._ends is None or len(self._ends) != len(self.decisions):
            rows = [(d.start, d.stop, d.accepted) for d in self.decisions]
            self._ends = np.array(rows, dtype=np.int64).reshape(-1, 3)
        return self._ends

    def candidate_rows(self, t) -> np.ndarray:
        """[start_s, end_s, accepted] per candidate (kept in the run file for the plots); a rest the review
        dropped is not accepted. ``t``: the run's times, or a function giving them at samples
        (:meth:`Source.times_at`)."""
        m = self.mask if self.mask.ndim == 1 else self.mask.any(axis=1)
        ends = self.candidate_ends()
        a, b = ends[:, 0], ends[:, 1]
        if len(ends) and np.all(b > a) and np.all(a[1:] >= b[:-1]) and a[0] >= 0 and b[-1] <= len(m):
            # the detector's spans, in order and apart: one reduction over the mask's [start, stop) of each (the
            # reductions between them, over [stop, next start), are dropped)
            cut = np.column_stack((a, b)).reshape(-1)
            any_in = np.logical_or.reduceat(m, cut[:-1] if cut[-1] == len(m) else cut)[0::2]
        else:  # any spans: the rest samples before each sample
            held = np.concatenate(([0], np.cumsum(m, dtype=np.int64)))
            any_in = held[b] > held[a]
        kept = (ends[:, 2] != 0) & any_in
        at = np.concatenate((ends[:, 0], ends[:, 1] - 1))
        tt = t(at) if callable(t) else np.asarray(t)[at]
        return np.column_stack((tt[: len(ends)], tt[len(ends) :], kept.astype(np.float64))).reshape(-1, 3)


@dataclass
class Outcome:
    """What :func:`run` did: the plan, the model used, the stages' results, and either the whole run
    with its outputs (``arrays``, one chunk in memory) or the ends of the outputs written (``ends``)."""

    model: Model
    plan: Plan
    n: int
    axis_names: np.ndarray
    t_ends: tuple[float, float]
    clipped: np.ndarray  # (n_axes,) samples not used per axis
    arrays: dict | None = None
    ends: dict = field(default_factory=dict)
    rests: RestOutcome | None = None
    applied: list[int] | None = None  # zero-velocity updates applied per axis
    fixes: list[int] | None = None  # fixes per axis
    tune: object = None  # (TuneResult, seconds)
    envelope: object = None  # accelnav.estimate.envelope.Envelope of a chunked run's series (Job.envelope)
    checks: object = None  # consistency.SmoothChecks (accelnav.data.smoothing adds them)
    store_in_memory: bool = True
    streamed: str = ""
    written: list = field(default_factory=list)  # files written (filled in by the caller that writes them)


def budget_bytes(budget: int | None) -> int:
    """The memory budget in bytes (None: half of what the machine has available now)."""
    return chunked.memory_available() // 2 if budget is None else int(budget)


def store_memory(job: Job) -> int:
    """Bytes the chunked passes' store may take in memory: the budget given, else at most STORE_MEMORY (in
    memory the store never waits on the disk's write-back, 8 s of 17 at 1e7 samples, measured; a longer
    run's store goes to disk, so that its memory stays the chunk buffers whatever its length)."""
    return budget_bytes(job.budget) if job.budget is not None else min(budget_bytes(None), STORE_MEMORY)


def over_budget(label: str, n: int, n_axes: int, budget: int) -> str:
    return (
        f"{label}: {n} samples x {n_axes} axes need about {chunked.whole_bytes(n, n_axes) / 1e9:.3g} GB on the "
        f"whole-array path, over the memory budget of {budget / 1e9:.3g} GB (--memory-budget)"
    )


# the rest decision's peak per sample at 2 axes, measured a stage at a time (VmHWM): a run in memory holds its record
# whole (t; each axis' acceleration and clipped flag) and the detector's x and ok beside it (18 B an axis with the
# record's). On the stop-and-go bench record at 1e7 the whole decision streamed (a chunk at a time:
# zupt.decide_rests_read) takes 24 B (36 B before the decision kept its candidates as arrays, rests._Cands): the
# sums are read from checkpoints (accelnav.estimate.rests.SUMS_EVERY) and the window figures a run at a time
# (zupt._Spans), not held whole. A record that is one long rest takes the most: the detector's, that run's window
# figures and pieces. It was 86 B at 3e6 (55 B streamed); since the run's median
# partitions its variances in place and the pieces take that array as their scratch, 70 B at 3e6 and 69 B at 1e7
# (46 B streamed, bench_rest_stages.py). The bound is its, with the margin it had: 80 B
REST_SAMPLE_BYTES, REST_AXIS_BYTES = 28, 26
REST_FLOOR = 64 << 20  # a decision needing less is not refused by a smaller budget: the process itself takes more


def rest_bytes(n: int, n_axes: int) -> int:
    """Estimated peak memory of the rest decision (``--zupt auto``) over n samples: it reads every sample."""
    return int(n) * (REST_SAMPLE_BYTES + REST_AXIS_BYTES * n_axes)


def plan(n: int, n_axes: int, job: Job, *, label: str = "the run", to_file: bool = True, echo: bool = False) -> Plan:
    """The one path choice, from the run's size and what ``job`` asks: one chunk in memory for what needs
    every output sample at once, else chunked to the file; refused (UserError) when that does not fit, the rest
    decision (:func:`rest_bytes`) included."""
    budget = budget_bytes(job.budget)
    detect = "smooth" in job.stages and job.rests is not None and job.rests.detect
    if detect and rest_bytes(n, n_axes) > max(budget, REST_FLOOR):
        raise UserError(
            f"{label}: {n} samples x {n_axes} axes need about {rest_bytes(n, n_axes) / 1e9:.3g} GB in memory for the "
            f"rest decision of --zupt auto (it reads every sample), over the memory budget of {budget / 1e9:.3g} GB "
            "(--memory-budget); given rests (--zupt FILE) stream any length"
        )
    fits = chunked.whole_bytes(n, n_axes) <= budget
    needs = list(job.in_memory)
    if not to_file:
        needs.append("arrays returned in memory")
    if needs and not fits:
        raise UserError(f"{over_budget(label, n, n_axes, budget)}; bounded memory does not do {', '.join(needs)}")
    # --covariances within the budget: one chunk in memory, as before; over it, chunked (written chunk by chunk)
    # --tune within it: one chunk in memory, as before; over it, its likelihood read chunk by chunk (_tune); --plots
    # within it: one chunk in memory, every sample drawn; over it, chunked, drawn from the outputs' envelope
    held = [why for why, v in (("--covariances", job.covariances), ("the aids' consistency checks",
                               job.aided and job.checks), ("the input's truth", echo), ("--tune", job.tune is not None),
                               ("--plots", job.envelope)) if v]  # fmt: skip
    if needs or (fits and held):
        return Plan(True, max(n, 1), 1, budget, f"one chunk in memory ({', '.join(needs or held[:1])})")
    chunk = chunked.chunk_samples(n_axes, min(chunked.BUDGET, budget), job.covariances)
    chunks = -(-n // chunk)
    why = "one chunk" if chunks == 1 else f"{chunks} chunks of {chunk} samples"
    return Plan(False, chunk, chunks, budget, f"{why} (memory budget {budget / 1e9:.3g} GB)")


def rest_stage(
    model: Model,
    arrays: dict | None,
    rests: Rests,
    *,
    fixes=None,
    smooth_pass=None,
    review_budget: int | None = None,
    source: Source | None = None,
    chunk: int = 1 << 20,
) -> RestOutcome:
    """The rest decision, called here and nowhere else: detected rests (``rests.detect``: the candidates and
    the decision on each, accelnav.estimate.zupt.decide_rests, weighed against the run's position ``fixes``)
    then their review (accelnav.estimate.pipeline.disagreeing_rests: whole-run smoothings, done when the run
    fits ``review_budget`` bytes on the whole-array path, None: always; ``RestOutcome.reviewed`` says
    whether it was), or the given mask;
    ``smooth_pass(extras, at)`` (:func:`smoother_pass` bound to this run) smooths it with trial aids in
    bounded memory and gives the velocities at samples ``at``, for a decision that needs a smoother pass.
    ``arrays`` None: the run is read from ``source`` ``chunk`` samples at a time for the decision, not held whole
    beside it (not reviewed: a run over the budget of the whole-array path)."""
    from accelnav.estimate import zupt

    params = zupt.ZuptParams() if rests.params is None else rests.params
    try:
        params = zupt.resolved(model, params)
    except ValueError as exc:
        raise UserError(f"--zupt-*: {exc}") from None
    if not rests.detect:
        if rests.spans is not None:
            return RestOutcome(None, None, params, spans=rests.spans)
        return RestOutcome(np.asarray(rests.mask, dtype=bool), rests.sigma, params)
    if arrays is None:  # read a chunk at a time (26 B a sample at 2 axes not held beside the detector's arrays)
        n, n_axes = source.n, len(source.axis_names)
        cands = candidate_mask(rests.candidates, n)
        found = zupt.decide_rests_read(source.read, n, n_axes, cands, model, params, fixes, chunk=chunk)
        gravity = zupt.gravity_axes_read(source.read, n, n_axes, model, chunk=chunk) if not found.mask.any() else []
        return RestOutcome(found.mask, None, params, found.decisions, gravity, detected=True,
                           reviewed=not found.mask.any())  # fmt: skip
    accel, clipped = arrays["accel"], arrays["clipped"]
    found = zupt.decide_rests(accel, clipped, candidate_mask(rests.candidates, len(accel)), model, params, fixes)
    mask, review, smoothed = found.mask, None, None
    if mask.any() and (review_budget is None or chunked.whole_bytes(len(mask), accel.shape[1]) <= review_budget):
        # the check that acts after the decision: rests a full smoother with the fixes or the other rests
        # refutes are dropped and named (pipeline.disagreeing_rests), before tuning and any advice
        from accelnav.estimate.pipeline import disagreeing_rests

        # without fixes, the review's smoother knows the velocity between rests from the model alone: a stop's
        # kinematics the decision saw outweighs it; with fixes its leave-one-out is theirs too
        stands = [] if any(fixes or []) else [
            (d.start, d.stop) for d in found.decisions if d.accepted and d.reason == "still stand"
        ]  # fmt: skip
        review = disagreeing_rests(arrays, model, mask, fixes=fixes, params=params, stands=stands)
        mask = review.kept.any(axis=1)
        smoothed, review = review.smoothed, replace(review, smoothed=None)  # held in one place only
    gravity = zupt.gravity_axes(accel, clipped, model) if not mask.any() else []
    return RestOutcome(mask, None, params, found.decisions, gravity, detected=True, review=review,
                       reviewed=review is not None or not found.mask.any(), smoothed=smoothed)  # fmt: skip


def candidate_mask(mask: np.ndarray | None, n: int) -> np.ndarray | None:
    """``mask`` checked as the candidates of an N-sample run (None stays None: the detector's own)."""
    if mask is None:
        return None
    m = np.asarray(mask)
    if m.shape != (n,) or m.dtype != bool:
        raise UserError(f"rest candidates: an (N,) bool mask of the run's {n} samples, got {m.dtype} {m.shape}")
    return m


def smoother_pass(model: Model, source: Source, extras, at: np.ndarray, *, workdir, budget: int | None = None):
    """One more pass of the chunked smoother over ``source`` with ``extras[j]`` (kf.Aids or measurements) per
    axis, in bounded memory (its output in a temporary file in ``workdir``, removed after); returns the
    smoothed velocity and its sd at samples ``at``, (n_axes, len(at), 2) [u, sd_u], float64."""
    import os
    import uuid

    at = np.asarray(at, dtype=np.int64)
    exs = [Aids.of(e) if not isinstance(e, Aids) else e for e in extras]
    # a file beside the others, not inside a TempFolder: the writer locks the folder it writes in
    out = Path(workdir) / f".accelnav-pass-{os.getpid()}-{uuid.uuid4().hex[:8]}.npz"
    try:
        chunk = chunked.chunk_samples(len(exs), min(chunked.BUDGET, budget_bytes(budget)))
        chunked.smooth_bounded(model, source.n, source.read, out, extras=exs, gates=[np.zeros(len(e)) for e in exs],
                               chunk=chunk, workdir=workdir, stages=("smooth",), store_memory=min(
                                   budget_bytes(budget), STORE_MEMORY))  # fmt: skip
        with chunked.NpzMember(out, "smooth_x") as x, chunked.NpzMember(out, "smooth_sd") as sd:
            return np.stack([x.rows_at(at, 1), sd.rows_at(at, 1)], axis=-1)
    finally:
        out.unlink(missing_ok=True)


def axis_extras(model: Model, n: int, j: int, fixes, rest: RestOutcome | None):
    """Axis j's aids as arrays for a run in memory: (its position fixes, its zero-velocity updates); the chunked
    passes make them chunk by chunk instead (:class:`_AxisAids`)."""
    from accelnav.estimate import zupt

    fx = Aids.of(list(fixes[j]) if fixes is not None else [])
    if rest is None:
        return fx, Aids.of([])
    m = rest.mask
    col = m if m.ndim == 1 else m[:, j]
    sigma = None if rest.sigma is None else np.asarray(rest.sigma)[:, j]
    return fx, zupt.axis_aids(np.broadcast_to(col, (n,)), sigma, model, rest.params)


def run(
    model: Model, source: Source, job: Job, out: str | Path | None = None, *, workdir=None, run_format: str = ""
) -> Outcome:
    """Filter or smooth ``source`` as ``job`` asks. With ``out`` the chunked path writes the run file
    itself (its format string ``run_format``: the caller's, a layer above); on the one-chunk path (and
    without ``out``) the whole run with its outputs comes back in ``Outcome.arrays`` for the caller to
    write."""
    n, n_axes = source.n, len(source.axis_names)
    if n < 1:
        raise UserError(f"{source.label}: 0 samples; nothing to process")
    if job.warm_start:
        from accelnav.model.edit import warm_started

        model = warm_started(model)
        note("--warm-start: bias prior at c1 + c2 = " + ", ".join(f"{a.c2:.4g}" for a in model.axes) + " m/s^2")
    smooth = "smooth" in job.stages
    echo = job.full and bool(source.extra_keys())
    p = plan(n, n_axes, job, label=source.label, to_file=out is not None, echo=echo)
    detect = smooth and job.rests is not None and job.rests.detect
    # the decision reads every sample: from memory, or a streamed run over the whole-array path's budget (never
    # reviewed) from the stream, a chunk at a time; given aids are read with the chunks
    streamed = detect and not p.whole and bool(source.streamed) and chunked.whole_bytes(n, n_axes) > p.budget
    arrays = source.whole() if (p.whole or (detect and not streamed)) else None
    rest = reuse = None
    if smooth and job.rests is not None:

        def smooth_pass(extras, at):
            return smoother_pass(model, source, extras, at, workdir=workdir or Path(out or ".").resolve().parent)

        rest = rest_stage(model, arrays, job.rests, fixes=job.fixes, smooth_pass=smooth_pass, review_budget=p.budget,
                          source=source, chunk=p.chunk)  # fmt: skip
        reuse, rest.smoothed = rest.smoothed, None
        if not p.whole and source.streamed and arrays is not None:
            # read whole for the decision only: the chunked passes read the stream again, a chunk at a time (at 1e7
            # samples and 2 axes the run held 310 MB more through them)
            source.arrays = arrays = None
        if rest.mask is None and p.whole:  # given as runs: per sample for the run in memory
            rest.mask, rest.sigma = rest.spans.painted()
        if job.rests.decided is not None:  # said where it happens: before tuning fits the figures to the rests
            job.rests.decided(rest)
    # the review's last smoothing had this run's model, fixes and rests: the one-chunk output when nothing else
    # is asked of it (no covariances, no tuned model); else it is not held through the passes
    if not (p.whole and smooth and reuse is not None and not job.covariances and job.tune is None):
        reuse = None
    outcome = Outcome(model, p, n, source.axis_names, source.t_ends, np.zeros(n_axes, dtype=np.int64), rests=rest,
                      streamed=source.streamed)  # fmt: skip
    if smooth and job.tune is not None:
        model = outcome.model = _tune(model, arrays if p.whole else source, job, rest, source.label, outcome)
    if p.whole:
        _whole(model, arrays, job, rest, outcome, reuse)
    else:
        _chunked(model, source, job, rest, out, workdir, outcome, run_format)
    return outcome


def _tune(model: Model, run, job: Job, rest: RestOutcome | None, label: str, outcome: Outcome) -> Model:
    """The tune search on ``run``: the arrays in memory (one chunk), or the :class:`Source` read a chunk at a time
    for every evaluation of the likelihood, its aids made for each chunk (:class:`_AxisAids`), in the memory of
    a chunk whatever the run's length."""
    from accelnav.estimate import tune

    t0 = [time.monotonic()]

    def announce(*a) -> None:
        if job.tune.announce is not None:
            job.tune.announce(*a)
        t0[0] = time.monotonic()

    bounds = dict(max_evaluations=job.tune.max_evaluations, max_seconds=job.tune.max_seconds, announce=announce)
    try:
        if isinstance(run, Source):
            n_axes = len(run.axis_names)
            _, aids = _AxisAids.each(model, job.fixes, rest, n_axes)
            chunk = tune.chunk_samples(n_axes, min(chunked.BUDGET, outcome.plan.budget))
            tuned, r = tune.tune_data(model, tune.RunData(run.n, n_axes, run.read, aids, chunk), **bounds)
        else:
            kw = {} if rest is None else dict(rest=rest.mask, rest_sigma=rest.sigma, params=rest.params)
            tuned, r = tune.tune_run(model, run, fixes=job.fixes, **bounds, **kw)
    except ValueError as exc:
        raise UserError(f"{label}: --tune: {exc}") from None
    outcome.tune = (r, time.monotonic() - t0[0])
    return tuned


def _whole(model: Model, arrays: dict, job: Job, rest: RestOutcome | None, outcome: Outcome, smoothed=None) -> None:
    """One chunk in memory: the whole-array kernels, then the checks. ``smoothed``: this very smoothing, made
    already (the rests' review's last, :func:`rest_stage`), taken rather than made again."""
    if "smooth" in job.stages:
        kw = {} if rest is None else dict(rest=rest.mask, rest_sigma=rest.sigma, zupt_params=rest.params)
        if smoothed is not None:
            check_run(arrays, model, "smooth_run")
            res = {**_fresh(arrays), **smoothed}  # the input's other keys beside its outputs, as smooth_arrays
        else:
            res = smooth_arrays(arrays, model, fixes=job.fixes, covariances=job.covariances, **kw)
        if rest is not None and rest.detected:  # for the plots: [start_s, end_s, accepted] per candidate
            t = res["t"]
            res["zupt_candidates"] = rest.candidate_rows(t)
        if rest is not None:
            outcome.applied = [int(c) for c in res["zupt"].sum(axis=0)]
        if job.fixes is not None:
            outcome.fixes = [len(f) for f in job.fixes]
    else:
        res = filter_arrays(arrays, model, covariances=job.covariances)
    outcome.arrays = res
    outcome.clipped = res["clipped"].sum(axis=0)


class _AxisAids(chunked.ChunkAids):
    """Axis j's aids for the chunked passes, made chunk by chunk: its position fixes (few, held whole, sorted
    stably by sample) and the zero-velocity updates of its rests (zupt.RestSpans.updates, made for the chunk's
    samples alone), in the order the whole run's ``Extras.of(fixes.concat(rests))`` gives them: by sample, a
    fix before a rest's update at the same sample; the updates are marked (the run file's ``zupt``).
    ``every``: a ``zupt_nis`` row per update (``--full``); else only each rest's first update's, the one the NIS
    checks read (the one-chunk file keeps the same: accelnav.data.runfile.compact)."""

    def __init__(self, model: Model, j: int, fixes: Aids, spans, params, every: bool = False, fill=None) -> None:
        from accelnav.estimate import fastsmooth

        self.model, self.j, self.spans, self.params, self.every = model, j, spans, params, every
        self.fx = fastsmooth.Extras.of(fixes)
        # the zupt_nis rows over the run: one per update, or one per rest (each rest's first update is applied:
        # rests are never gated per update)
        self.nis_rows = 0 if spans is None else spans.count(j, model, params) if every else _rests(spans, j)
        self.count = len(self.fx) + self.nis_rows
        self.at = 0  # the first fix of the chunk last asked for (its innovations follow at once)
        self.fix_nis = np.full(len(self.fx), np.nan)  # each fix's NIS, in the given order, as the filter meets it
        self.rests = None  # each rest's first and end sample and its id (_firsts), made when innovations first come
        self.last_rest = -1  # the rest of the last update met (chunk to chunk): a new one's first update is marked
        self.fill = _UpdateFill() if fill is None else fill

    @classmethod
    def each(cls, model: Model, fixes, rest, n_axes: int, every: bool = False) -> tuple[list[Aids], list[_AxisAids]]:
        """Every axis's fixes and its aids made chunk by chunk, from the run's fixes (per axis, or None) and
        rests (RestOutcome, or None): the one recipe of the chunked passes and of --tune's likelihood."""
        fx = [Aids.of(list(fixes[j]) if fixes is not None else []) for j in range(n_axes)]
        spans, params = (None, None) if rest is None else (rest.runs(n_axes), rest.params)
        fill = _UpdateFill()  # the axes take their turns: one set of constant parts for all
        return fx, [cls(model, j, fx[j], spans, params, every, fill) for j in range(n_axes)]

    def between(self, s: int, e: int) -> chunked.Piece:
        from accelnav.estimate import fastsmooth

        fx = self.fx
        a, b = int(np.searchsorted(fx.k, s)), int(np.searchsorted(fx.k, e))
        self.at = a
        if self.spans is None:
            zs = Aids.of([])
        else:  # Aids.zero_velocity's arrays, their constant parts shared (read-only) rather than made per chunk
            ks, sd = self.spans.updates(self.j, s, e, self.model, self.params)
            ks = np.asarray(ks, dtype=np.int64).reshape(-1)
            h, zero, ones, order = self.fill.take(len(ks))
            sd = np.asarray(sd, dtype=np.float64)
            if sd.ndim == 0:  # one sigma for all (detected rests): its variance shared like h, not made per chunk
                R = self.fill.variances(len(ks), float(sd**2))
            else:
                R = sd**2 if sd.shape == ks.shape else np.broadcast_to(sd**2, ks.shape).copy()
            zs = Aids(ks, h, zero, R)
            if a == b and not np.any(ks[1:] < ks[:-1]):  # rests alone, in order: the sort below would change nothing
                return chunked.Piece(fastsmooth.Extras(ks, h, zero, zs.R, order), zero, ones)
        k = np.concatenate((fx.k[a:b], zs.k))
        order = np.argsort(k, kind="stable")
        h, z, R = (np.concatenate((f[a:b], r))[order] for f, r in ((fx.h, zs.h), (fx.z, zs.z), (fx.R, zs.R)))
        marked = (np.arange(len(k)) >= b - a)[order]
        return chunked.Piece(fastsmooth.Extras(k[order], h, z, R, order), np.zeros(len(k)), marked)

    def innovations(self, piece: chunked.Piece, done: np.ndarray, y: np.ndarray, S: np.ndarray, t: np.ndarray, s: int):
        """The fixes' NIS kept (fix_nis, few); the applied updates' rows of ``zupt_nis`` returned, as
        smooth_arrays makes them: [t, axis, y^2 / S, 1 for the first update of its rest] (without ``every``, the
        first updates' alone, their NIS alone computed)."""
        if len(self.fx):
            fix = ~piece.marked & done
            self.fix_nis[self.fx.order[self.at + piece.ex.order[fix]]] = y[fix] * y[fix] / S[fix]
        rest = piece.marked & done
        idx = None if rest.all() else np.flatnonzero(rest)  # rests alone, all applied: every aid of the piece
        k = piece.ex.k if idx is None else piece.ex.k[idx]
        if not len(k):
            return np.zeros((0, 4))
        pos = self._firsts(k)
        if not self.every:
            at = pos if idx is None else idx[pos]
            ya = y[at]
            return np.column_stack((t[piece.ex.k[at] - s], np.full(len(at), self.j), ya * ya / S[at], np.ones(len(at))))
        first = np.zeros(len(k), dtype=bool)
        first[pos] = True
        ya, Sa = (y, S) if idx is None else (y[idx], S[idx])
        return np.column_stack((t[k - s], np.full(len(k), self.j), ya * ya / Sa, first))

    def _firsts(self, k: np.ndarray) -> np.ndarray:
        """Where in the applied updates ``k`` (sorted) a rest's first update is: the first of each rest met here
        but of the rest the last chunk ended in. A rest is a run of touching spans (zupt.RestSpans.rest_of, its
        id the index of its first span), so its updates' positions come from its ends, not from each update."""
        if self.rests is None:  # --tune's aids never ask: 24 B a rest held for nothing
            self.rests = self.spans.rests(self.j)
        starts, ends, ids = self.rests
        r0, r1 = int(np.searchsorted(ends, k[0], side="right")), int(np.searchsorted(starts, k[-1], side="right"))
        p, q = np.searchsorted(k, starts[r0:r1]), np.searchsorted(k, ends[r0:r1])
        held = p < q
        p, ids = p[held], ids[r0:r1][held]
        new = ids != self.last_rest  # only the first can be the last chunk's
        self.last_rest = int(ids[-1])
        return p[new]


class _UpdateFill:
    """The constant parts of zero-velocity updates (kf.Aids.zero_velocity: h = [0, 1, 0, 0], z = 0; a Piece's gates
    0, marked, order 0..n-1; R where one sigma is all the updates') as read-only views of n rows, made once and grown
    when a chunk has more updates: a chunk's fresh arrays of 1e5 and more rows cost their pages' faults, each call
    (bench/speed/bench_rest_updates.py)."""

    def __init__(self) -> None:
        self.n = -1
        self.R, self.r = np.zeros(0), None

    def variances(self, n: int, r: float) -> np.ndarray:
        """n updates' R, each ``r``, read-only; made again for another r (the same double: same bits, but a NaN)."""
        if n > len(self.R) or r != self.r:
            self.R = np.full(max(n, len(self.R) + len(self.R) // 4) if n > len(self.R) else len(self.R), r)
            self.R.flags.writeable = False
            self.r = r
        return self.R[:n]

    def take(self, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        if n > self.n:  # a quarter more: the axes' and chunks' counts differ a little (made again, pages faulted)
            size = max(n, self.n + self.n // 4)
            h = np.zeros((size, 4))
            h[:, 1] = 1.0
            self.parts = (h, np.zeros(size), np.ones(size, dtype=bool), np.arange(size))
            for a in self.parts:
                a.flags.writeable = False
            self.n = size
        return tuple(a[:n] for a in self.parts)


def _rests(spans, j: int) -> int:
    """Axis j's rests that hold an update: its rests (zupt.RestSpans.rests: touching spans are one) of at least
    one sample; each starts with an update, whatever every_s."""
    starts, ends, _ = spans.rests(j)
    return int(np.sum(ends > starts))


class _Times:
    """The run's t at the ends of --zupt auto's candidates (RestOutcome.candidate_rows asks for those samples),
    kept as the chunks are read."""

    def __init__(self, rest: RestOutcome, n: int) -> None:
        ends = rest.candidate_ends()[:, :2] - np.array([0, 1])
        self.k = np.unique(ends[(ends >= 0) & (ends < n)])
        self.t = np.full(len(self.k), np.nan)
        self.seen = np.zeros(len(self.k), dtype=bool)

    def read(self, s: int, t: np.ndarray) -> None:
        lo, hi = np.searchsorted(self.k, s), np.searchsorted(self.k, s + len(t))
        self.t[lo:hi] = t[self.k[lo:hi] - s]
        self.seen[lo:hi] = True

    def at(self, k: np.ndarray, times_at: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """t at samples ``k``: those kept, else (a sample not asked for, or not read) ``times_at``'s."""
        k = np.asarray(k, dtype=np.int64)
        i = np.minimum(np.searchsorted(self.k, k), max(len(self.k) - 1, 0))
        if len(self.k) and np.array_equal(self.k[i], k) and self.seen[i].all():
            return self.t[i]
        return times_at(k)


class _RunEnvelope:
    """What the figures of a chunked run draw, kept as the chunks go by (accelnav.estimate.envelope.Envelope): the
    time, plain double integration of the input (accelnav.estimate.kf.double_integrate, its sums carried from
    chunk to chunk: the same doubles), the model's mean bias, the input's truth when it is held, the filter's and
    the smoother's states with their +-1 sigma bands (``tap``) and the zero-velocity updates applied."""

    def __init__(self, model: Model, n: int, source: Source) -> None:
        from accelnav.estimate.envelope import Envelope

        self.env, self.n, self.source = Envelope(n), n, source
        self.designs = [axis_design(model, j) for j in range(len(source.axis_names))]
        # per axis: the running sum of a, of the position steps, the last u, a, and the last valid a (forward fill)
        self.carry = [[0.0, 0.0, 0.0, 0.0, 0.0] for _ in self.designs]
        self.held: dict[tuple[str, int, int], np.ndarray] = {}
        self.done: set[int] = set()

    def read(self, s: int, t: np.ndarray, accel: np.ndarray, clipped: np.ndarray) -> None:
        if s in self.done:  # a chunk read again (a later pass) is added once
            return
        self.done.add(s)
        e = s + len(t)
        self.env.add("t", s, t)
        truth = self.source.arrays or {}
        for j, d in enumerate(self.designs):
            self.env.add(f"dr/{j}", s, self._integrate(j, s, accel[:, j], ~clipped[:, j], d.Ts))
            self.env.add(f"bias/{j}", s, d.eps_mean - d.axis.c1 * d.phi ** np.arange(s, e))
            for key in ("r", "u", "a", "eps"):
                if key in truth:
                    self.env.add(f"{key}/{j}", s, np.asarray(truth[key][s:e, j], dtype=np.float64))

    def _integrate(self, j: int, s: int, a: np.ndarray, ok: np.ndarray, Ts: float) -> np.ndarray:
        """double_integrate's [r, u] of samples s.., from the sums carried over the samples before."""
        A, Rm, u_prev, a_prev, last = self.carry[j]
        m = len(a)
        idx = np.maximum.accumulate(np.where(ok, np.arange(m), -1))
        a = np.where(idx >= 0, np.asarray(a, dtype=np.float64)[np.maximum(idx, 0)], last)  # invalid: the last valid
        Aext = np.cumsum(np.concatenate(([A], a)))  # A[s-1], A[s], .. (u[k] = Ts A[k-1])
        u = Ts * Aext[:-1]
        if s == 0:
            w = Ts * u[:-1] + 0.5 * Ts * Ts * a[:-1]  # r[k] = the sum of w up to k-1
            r = np.cumsum(np.concatenate(([0.0], w)))
        else:
            w = Ts * np.concatenate(([u_prev], u[:-1])) + 0.5 * Ts * Ts * np.concatenate(([a_prev], a[:-1]))
            r = np.cumsum(np.concatenate(([Rm], w)))[1:]
        self.carry[j] = [float(Aext[-1]), float(r[-1]), float(u[-1]), float(a[-1]), float(a[-1])]
        return np.column_stack((r, u))

    def tap(self, key: str, j: int, s: int, values: np.ndarray) -> None:
        if j < 0:  # the zero-velocity updates applied, every axis
            self.env.add(key, s, values)
            return
        stage, what = key.split("_", 1)
        if what == "x":
            self.held[stage, j, s] = np.array(values, dtype=np.float64)
            self.env.add(f"{stage}_x/{j}", s, values)
        elif what == "sd":  # after the chunk's means: its band
            x = self.held.pop((stage, j, s))
            self.env.add(f"{stage}_lo/{j}", s, x - values)
            self.env.add(f"{stage}_hi/{j}", s, x + values)


def _chunked(model, source: Source, job: Job, rest, out, workdir, outcome: Outcome, run_format: str) -> None:
    """The passes over chunks, the output written in place (accelnav.estimate.chunked); the aids made for each
    chunk as the forward pass reaches it (:class:`_AxisAids`), the fixes' times read as it goes."""
    n, n_axes = source.n, len(source.axis_names)
    smooth = "smooth" in job.stages
    fixes = job.fixes if smooth else None
    aided = smooth and job.aided
    # --covariances smoothed writes the filter's states too, as the one-chunk path (smooth_arrays) does
    # --plots: the figures draw the filter's states too: they are computed, and so written, beside the smoother's
    stages = ("filt", "smooth") if smooth and (job.covariances or job.envelope) else job.stages
    env = _RunEnvelope(model, n, source) if job.envelope else None
    fx, extras = _AxisAids.each(model, fixes, rest if smooth else None, n_axes, every=job.full or job.covariances)
    extras = extras if aided else None
    fix_t = [np.full(len(f), np.nan) for f in fx]  # the run's t at each fix, filled as the chunks are read
    echo = source.extra_keys() if job.full else {}
    counts: dict[int, np.ndarray] = {}
    # --zupt auto's candidates' first and last samples (zupt_candidates' times), their t read as the chunks go by:
    # Source.times_at would read the input once more after the passes (0.27 s of 2.1 at 1e6 rows, measured)
    cand = _Times(rest, n) if aided and rest is not None and rest.detected else None

    def read(s: int, e: int):
        t, accel, c = source.read(s, e)
        if env is not None:
            env.read(s, t, accel, c)
        # by chunk start: a chunk read twice counts once; none clipped (the rule) is told by one pass
        counts[s] = c.sum(axis=0) if c.any() else np.zeros(c.shape[1], dtype=np.int64)
        for f, ft in zip(fx, fix_t, strict=True):
            here = (f.k >= s) & (f.k < e)
            ft[here] = t[f.k[here] - s]
        if cand is not None:
            cand.read(s, t)
        return t, accel, c

    def more(applied: list[np.ndarray]) -> dict[str, np.ndarray]:
        """The fixes' rows as the one-chunk path writes them (the rests' samples went into ``zupt`` chunk by
        chunk), and the input's other keys."""
        add = dict(echo)
        if not aided:
            if job.covariances and smooth:  # the one-chunk file's members, empty without aids
                add.update(fixes=np.zeros((0, 4)), fix_nis=np.zeros(0), zupt_nis=np.zeros((0, 4)))
            return add
        rows = [(ft, j, z, np.sqrt(r)) for j, f in enumerate(fx) for ft, z, r in zip(fix_t[j], f.z, f.R, strict=True)]
        add["fixes"] = np.array(rows, dtype=np.float64).reshape(-1, 4)
        # the aids' NIS as the one-chunk path writes them (the rests' rows went into zupt_nis chunk by chunk)
        add["fix_nis"] = np.concatenate([a.fix_nis for a in extras])
        if rest is None:
            add["zupt_nis"] = np.zeros((0, 4))
        if rest is not None and rest.detected:
            add["zupt_candidates"] = rest.candidate_rows(lambda k: cand.at(k, source.times_at))
        return add

    def kept(applied: list[np.ndarray]) -> dict[str, np.ndarray]:
        add = more(applied)
        if env is not None:
            env.env.extra.update({k: v for k, v in add.items() if k in ("fixes", "zupt_candidates")})
        return add

    info = chunked.smooth_bounded(
        model, n, read, out, axis_names=source.axis_names, extras=extras, chunk=outcome.plan.chunk,
        workdir=workdir, run_format=run_format, more=kept, stages=stages, store_memory=store_memory(job),
        full=job.full, marks="zupt" if aided or (smooth and job.covariances) else "", covariances=job.covariances,
        nis="zupt_nis" if aided and rest is not None else "",
        tap=None if env is None else env.tap,
    )  # fmt: skip
    outcome.envelope = None if env is None else env.env
    ends = {k: v[:, None, :] for k, v in info["last"].items() if k.startswith("filt_")}
    ends.update({k: v[:, None, :] for k, v in info["first"].items() if k.startswith("smooth_")})
    outcome.ends = ends
    outcome.store_in_memory = info["store_in_memory"]
    outcome.clipped = np.sum(list(counts.values()), axis=0) if counts else np.zeros(n_axes, dtype=np.int64)
    if rest is not None and smooth:
        outcome.applied = [int(c) for c in info["marked"]]
    if fixes is not None:
        outcome.fixes = [len(f) for f in fixes]


# -- one chunk in memory: the whole-array entry points of the kernels ---------------------------------------------


class _Out:
    """The per-axis outputs, written axis by axis into arrays allocated once (no list then np.stack,
    which held every array twice at the peak)."""

    def __init__(self, n_axes: int, n: int, stages: tuple[str, ...], covariances: bool):
        self.arrays: dict[str, np.ndarray] = {}
        for st in stages:
            self.arrays[f"{st}_x"] = np.empty((n_axes, n, 4))
            self.arrays[f"{st}_sd"] = np.empty((n_axes, n, 4))
            if covariances:
                self.arrays[f"{st}_P"] = np.empty((n_axes, n, 4, 4))
        if covariances and "filt" in stages:
            self.arrays["filt_x_prior"] = np.empty((n_axes, n, 4))
            self.arrays["filt_P_prior"] = np.empty((n_axes, n, 4, 4))

    def plain(self, j: int, d, z: np.ndarray, valid: np.ndarray) -> None:
        """Axis j by the compiled plain path, its means written straight into the output rows: what
        fastsmooth.smooth_plain does, without its two (N, 4) copies and without the priors (a matmul over
        every sample) unless the covariances were asked for."""
        from accelnav.estimate import fastsmooth

        a = self.arrays
        z = np.asarray(z, dtype=np.float64)
        ok = np.isfinite(z) & np.asarray(valid, dtype=bool)
        mask = None if ok.all() else ok
        g = fastsmooth.plain_gains(d, len(z), mask)
        xf = a["filt_x"][j]
        xs = a["smooth_x"][j] if "smooth_x" in a else np.empty_like(xf)
        fastsmooth.plain_data(d, np.where(ok, z, 0.0), mask, g, out=(xf, xs))
        self.put(j, "filt", None, g.P_post)
        self.put(j, "smooth", None, g.Ps)
        if "filt_x_prior" in a:
            x_prior = a["filt_x_prior"][j]
            x_prior[0] = d.x0
            x_prior[1:] = xf[:-1] @ np.asarray(d.F).T + np.asarray(d.b)
            self.put(j, "filt_prior", None, g.P_prior)

    def put(self, j: int, key: str, x: np.ndarray | None, Pp: np.ndarray | None = None) -> None:
        """Axis j of ``key`` (a state, e.g. "smooth") from its (N, 4) means and (N, 10) packed covariances."""
        a = self.arrays
        suffix = "_prior" if key.endswith("_prior") else ""
        stage = key.removesuffix("_prior")
        if f"{stage}_x{suffix}" not in a:
            return
        if x is not None:  # None: already written in place
            a[f"{stage}_x{suffix}"][j] = x
        if not suffix:
            sd = a[f"{stage}_sd"][j]
            np.take(Pp, _DIAG, axis=1, out=sd, mode="clip")  # "raise" would buffer out
            np.sqrt(sd, out=sd)
        if f"{stage}_P{suffix}" in a:
            np.take(Pp, _FULL, axis=1, out=a[f"{stage}_P{suffix}"][j].reshape(len(Pp), 16), mode="clip")


def _plain_ok(d) -> bool:
    """The plain path needs P0 without (r, u)-(a, eps) cross terms (accelnav.estimate.fastsmooth.smooth)."""
    return not np.any(np.asarray(d.P0)[:2, 2:] != 0)


def _fresh(arrays: dict) -> dict:
    """``arrays`` without a previous run's outputs, so that no old covariance sits beside new means."""
    return {k: v for k, v in arrays.items() if not k.startswith(("filt_", "smooth_"))}


def filter_arrays(arrays: dict, model: Model, *, covariances: bool = True) -> dict:
    """The filter over every axis of a run in memory, one chunk: ``arrays`` with filt_x, filt_sd (with
    ``covariances`` also filt_P and the priors filt_x_prior, filt_P_prior)."""
    from accelnav.estimate import fastsmooth

    check_run(arrays, model, "filter_run")
    n, n_axes = arrays["accel"].shape
    res_out = _Out(n_axes, n, ("filt",), covariances)
    for j in range(n_axes):
        d = axis_design(model, j)
        z, valid = arrays["accel"][:, j], ~arrays["clipped"][:, j]
        if _plain_ok(d):
            res_out.plain(j, d, z, valid)
            continue
        res = fastsmooth.smooth_general(d, z, valid=valid)
        res_out.put(j, "filt", res.x_post, res.P_post)
        res_out.put(j, "filt_prior", res.x_prior, res.P_prior)
        del res
    out = _fresh(arrays)
    out.update(res_out.arrays)
    return out


def smooth_arrays(
    arrays: dict,
    model: Model,
    *,
    fixes=None,
    rest: np.ndarray | None = None,
    zupt_params=None,
    rest_sigma: np.ndarray | None = None,
    covariances: bool = True,
) -> dict:
    """Filter and smoother over every axis of a run in memory, one chunk (see
    :func:`accelnav.estimate.pipeline.smooth_run` for the keys it adds)."""
    from accelnav.estimate import fastsmooth, zupt

    check_run(arrays, model, "smooth_run")
    params = zupt.ZuptParams() if zupt_params is None else zupt_params
    n = len(arrays["t"])
    n_axes = len(arrays["axis_names"])
    r = None if rest is None else RestOutcome(np.asarray(rest, dtype=bool), rest_sigma, params)
    rest2 = None if r is None else np.broadcast_to(r.mask[:, None] if r.mask.ndim == 1 else r.mask, (n, n_axes))
    res_out = _Out(n_axes, n, ("filt", "smooth"), covariances)
    applied = np.zeros((n, n_axes), dtype=bool)
    fix_rows, fix_nis, zupt_nis = [], [], []
    for j in range(n_axes):
        d = axis_design(model, j)
        fx, za = axis_extras(model, n, j, fixes, r)
        extras = fx.concat(za)
        gates = np.zeros(len(fx) + len(za))  # no innovation gate: rests are gated whole by the decision
        z, valid = arrays["accel"][:, j], ~arrays["clipped"][:, j]
        if not len(extras) and _plain_ok(d):
            res_out.plain(j, d, z, valid)
            continue
        res = fastsmooth.smooth_general(d, z, valid=valid, extras=fastsmooth.Extras.of(extras), gates=gates)
        res_out.put(j, "filt", res.x_post, res.P_post)
        res_out.put(j, "filt_prior", res.x_prior, res.P_prior)
        res_out.put(j, "smooth", res.xs, res.Ps)
        if len(za):
            applied[za.k[res.applied[len(fx) :]], j] = True
        fix_rows += list(zip(arrays["t"][fx.k], [j] * len(fx), fx.z, np.sqrt(fx.R), strict=True))
        if len(extras):  # NIS only where there are aids: the plain path pays nothing
            # the innovations as the compiled filter met them (consistency.aid_innovations replays the same)
            sel = np.flatnonzero(res.applied)
            used = extras.take(sel)
            y, S = res.y[sel], res.S[sel]
            nis = y * y / S
            n_fix_used = int(np.sum(res.applied[: len(fx)]))  # fixes are never gated: all of them
            fix_nis += list(nis[:n_fix_used])
            zk = used.k[n_fix_used:]
            if len(zk):
                # the first update of each rest carries the velocity gathered since the last aid: the test of
                # the model; the later ones mostly test the zero-velocity sigma, a chosen pseudo-noise
                moving = np.concatenate(([0], np.cumsum(~rest2[:, j])))  # non-rest samples before each sample
                first = np.ones(len(zk), dtype=bool)
                first[1:] = moving[zk[1:]] != moving[zk[:-1]]
                zupt_nis.append(np.column_stack((arrays["t"][zk], np.full(len(zk), j), nis[n_fix_used:], first)))
        del res
    out = _fresh(arrays)
    out.update(res_out.arrays)
    out["zupt"] = applied
    out["fixes"] = np.array(fix_rows, dtype=np.float64).reshape(-1, 4)
    out["fix_nis"] = np.array(fix_nis, dtype=np.float64)
    out["zupt_nis"] = np.concatenate(zupt_nis) if zupt_nis else np.zeros((0, 4))
    return out
