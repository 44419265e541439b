"""The rest decision: each candidate of the detector (accelnav.estimate.zupt.candidates) is a hypothesis, "the
body stands still here", accepted only if a zero velocity there agrees with everything else the record knows.

The evidence: a kinematic filter
--------------------------------
Per axis, the state s = (r, u, e): position, velocity and the *level* e, everything that adds to the true
acceleration in the measured one (the bias left after the model's mean, gravity leaking through a tilt, a
grade). Driven by the measured acceleration x (the model's bias mean removed):

    u[k+1] = u[k] + Ts (x[k] - e[k]),   r[k+1] = r[k] + Ts u[k],   e[k+1] = e[k] + w,  w ~ N(0, q Ts)

(q = ``level_walk``^2) plus the velocity noise of integrating the sensor's own noise (R Ts per second).
Between two events the state moves in closed form (cumulative sums of x: the cost is per event, not per
sample). Priors are diffuse: nothing is assumed about the start. Aids: the position fixes, and each
accepted rest as u = 0 at its first and last sample (sd ``sigma``): between them the rest's own
acceleration says what its level is.

The test of one candidate [a, b)
--------------------------------
Two filters, one forward in time and one backward (the same kinematics on the reversed record: velocity
changes sign, acceleration does not), each taken just *before* the candidate: the forward one at a knows
the fixes and accepted rests before it, the backward one at b - 1 those after it. Neither holds the
candidate's own updates: the test is leave-one-out without re-smoothing. Each is conditioned on the
candidate's level (its mean acceleration: under "rest" and under "cruise" alike that is the level there),
so the velocity is integrated with the level linear from the last aid's to the candidate's (a tilt
drifting at a steady rate costs nothing), and gives v +- sd per axis, sd widened by ``LEAK`` x (level
change) x (time since the last aid) (the level's path between is unknown) and ``drift`` x that time (a
mean acceleration error no level explains). On each side the chi-square of v over the axes is read on one
axis' scale (:func:`chi2_equivalent`), against ``gate`` (12: 3.5 sd):

* **moving**: above the gate on either side: the fixes or the other rests imply speed there (a cruise
  between fixes, a hand moving the box). A refusal needs no small sd: a large sd only makes it rarer.
* **level jumped**: the level moved by more than ``level_still`` from the last rest's with no motion
  between (the velocity integrated since stayed under 0.2 m/s: a ramp's or a push's quiet piece), or by
  more than ``level_max`` after a move; a candidate far less still than the record's proven rests
  (``LIKE`` x their median stillness) is held to ``UNLIKE`` x ``level_still`` after a move (a push held,
  not a foot that turned). A level that moved more than ``level_still`` and passes is a *hypothesis* (below).
* **consistent**: within the gate, and a side can tell (every axis' sd <= ``tell``; for a candidate far less
  still than the proven rests and shorter than ``start_s``, <= ``UNLIKE_TELL`` x ``tell``: a trunk mid-stride is that
  quiet for a tenth of a second).
* neither side can tell: the candidate is refused as **cannot tell**, unless another line of evidence
  decides:

  - **still start**: before any rest, a candidate that begins within ``start_within_s``, lasts
    ``start_s`` and is still at the sensor's own noise (variance <= ``still_k`` R) anchors: the run
    starts at rest, an assumption the report states; not made when the model's own prior lets the run
    start moving (its start-speed sd above ``tell``).
  - **still stand**: as still as the record's proven rests (<= max(``still_k``, 2 x their median)),
    lasting ``start_s``, with the kinematics of a stop: the speed integrated from the last stand (a rest
    of ``start_s`` at least, not a short piece that may be a ramp's) rose to a peak of 2 sd at least and
    came back to ``rel`` of it ("no deceleration" refuses a quiet stretch at cruise).
  - **a hypothesis**, before the first rest or where the record lost its rests: the candidate is taken as
    a rest and kept when the next ``CONFIRM`` candidates, tested with it, are consistent with motion
    between them (0.2 m/s; where the record had rests before, a stride's 1 m/s: a car's cruise pieces
    close on each other after small changes of speed); when one is moving or cannot be told, or none
    within ``WITHIN``, the filter goes back to before the hypothesis and on without it.

The positions, across it
------------------------
A quiet stretch at cruise can look still from either side alone: on a changing grade the level a side is
conditioned on hides the speed (a real car at 5 m/s on a hill read 0.7 +/- 0.5 m/s from the fix 3 s before).
The fixes also fix where the body is: where both sides know the position through the fixes, a rest puts the
forward side's position at its start and the backward side's at its end in one place (within the rest's own
sigma over its length). Their distance, against both sds widened like the velocity's, read as one axis'
chi-square (:meth:`_Decider._gap`), refutes it like a side's velocity does ("fixes imply it moved 14 m during
it"), and the pieces it touches fall with it (it is the fixes' refutation).

The fixed point, robust
-----------------------
The forward filter decides online (each accepted rest aids it from there on); the backward filter then
re-tests every accepted rest with all the others, from the other side and by the positions across it. Of
each run of consecutive accepted rests found moving, the worst is withdrawn, or the rest after it that the disagreement
came from when that one has less evidence of its own (a side that tells, or the stillness of a start or
stand; on a tie the shorter), and both filters run again, at most ``passes`` times; what still disagrees
then is withdrawn. No accepted rest vouches for another: each is re-tested against all the others at
every pass, and one that disagrees leaves.

What it costs: two runs over the events (candidates, fixes) per pass, each a few 3 x 3 operations per event,
in C beside the smoother's kernels (acn_kin_* in csrc/fastsmooth.c: the filter's steps, a forward side's whole
test in one call, the chi-square's tail, a candidate's statistics and peak speed, the whole backward run), the
forward filter's loop, its verdicts, hypotheses and words in Python (most of the cost left: a few tens of
microseconds per candidate test, against the plain smoother's fraction of one per sample): per sample it grows with the
density of candidates and with the passes and the hypotheses' replays, not with the record's length. A pass
after the first runs the forward filter again only from the first candidate whose veto is new (it resumes at a
mark the last pass left before that candidate's test: before it, nothing differs), the backward filter from the
start (bench/speed/bench_rest_decision.py measures it beside the plain smoother and beside the numpy filter it
replaced).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

DIFFUSE = (1e10, 1e4, 1e2)  # prior variances of r [m^2], u [(m/s)^2], e [(m/s^2)^2]: nothing assumed


@dataclass(frozen=True)
class Side:
    """What one filter (before or after the candidate) says about its velocity."""

    v: np.ndarray  # (n_axes,) m/s, mean velocity at the candidate given its level
    sd: np.ndarray  # (n_axes,) m/s
    chi2: float  # mean over axes of v^2 / (sd^2 + sigma^2)
    source: str  # the nearest aid that informs it ("the rest at 3.10 s", "the fix at 12.0 s", "no aid")
    fix: bool  # a fix informs it
    r: np.ndarray | None = None  # (n_axes,) m, position at the candidate's edge given its level
    r_sd: np.ndarray | None = None  # (n_axes,) m, its sd
    norms: tuple[float, float] | None = None  # (|v|, rms of sd) as the kernel summed them; None: from v and sd


def _made(v, sd, chi2, source, fix, r, r_sd, norms) -> Side:
    """A Side without the frozen dataclass' per-field checks (its __init__ sets each field through
    object.__setattr__; a forward pass makes hundreds): the same fields, set at once."""
    s = object.__new__(Side)
    s.__dict__.update(v=v, sd=sd, chi2=chi2, source=source, fix=fix, r=r, r_sd=r_sd, norms=norms)
    return s


@dataclass(frozen=True)
class Candidate:
    start: int
    stop: int
    level: np.ndarray  # (n_axes,) mean acceleration (model's bias mean removed), m/s^2
    still: float  # mean over axes of its variance / R


class _Kinematic:
    """The kinematic filter of the module docstring over one direction of time of one record.

    The axes do not couple: each holds its state (r, u, e) and the six entries of its symmetric covariance, 9
    doubles [r, u, e, Prr, Pru, Pre, Puu, Pue, Pee], in one C buffer; the steps on it (propagation, an aid, a
    side's test, the level's jump) are the kernels' (acn_kin_* in csrc/fastsmooth.c). A decision makes a few
    hundred small steps per pass, each a few dozen multiplications per axis: Python's own per-step overhead cost
    more than the arithmetic (bench/speed/bench_rest_decision.py)."""

    def __init__(self, x: np.ndarray, Ts: float, R: np.ndarray, q: float, reverse: bool = False):
        """The filter before any event on the record ``x`` (N, n_axes), its rows last first when ``reverse``."""
        from accelnav.estimate.fastsmooth import _lib  # the kernels (not loaded at the package's import)

        mod = _lib()
        self.ffi, self.lib = mod.ffi, mod.lib
        n, self.n_axes = x.shape
        self.Ts, self.q = Ts, q
        # V[k] = Ts sum_{i<k} x[i]; A[k] = Ts sum_{i<k} |x[i]|: how much moved; W[k] = Ts sum_{i<k} V[i]; in one
        # pass over the record (acn_kin_sums), numpy's cumsums' order
        self.V, self.A, self.W = (np.empty((n + 1, self.n_axes)) for _ in range(3))
        buf = self.ffi.from_buffer
        self.lib.acn_kin_sums(n, self.n_axes, buf("double[]", np.ascontiguousarray(x, dtype=np.float64)), reverse, Ts,
                              *(buf("double[]", a) for a in (self.V, self.A, self.W)))  # fmt: skip
        self.R = np.ascontiguousarray(R, dtype=np.float64)
        self.qv = self.R * Ts
        # the kernels read these through pointers made once (the arrays are kept alive beside them)
        self._V, self._W, self._A, self._R, self._qv = (
            self.ffi.from_buffer("double[]", a) for a in (self.V, self.W, self.A, self.R, self.qv)
        )
        self.s = self.ffi.new("double[]", [v for _ in range(self.n_axes) for v in (0.0, 0.0, 0.0, DIFFUSE[0],
                                           0.0, 0.0, DIFFUSE[1], 0.0, DIFFUSE[2])])  # fmt: skip
        self.k = 0
        self.aid_k = 0  # sample of the last aid
        self._res = self.ffi.new("double[4]")  # the figures of a test (test); its copies share it, read at once

    @property
    def X(self) -> np.ndarray:
        """(n_axes, 3): r, u, e per axis (a copy)."""
        return np.frombuffer(self.ffi.buffer(self.s), dtype=np.float64).reshape(self.n_axes, 9)[:, :3].copy()

    def copy(self) -> _Kinematic:
        new = object.__new__(_Kinematic)
        new.__dict__.update(self.__dict__)
        new.s = self.ffi.new("double[]", 9 * self.n_axes)
        self.ffi.memmove(new.s, self.s, self.ffi.sizeof(self.s))
        return new

    def to(self, k: int) -> None:
        """Propagate the state from sample self.k to sample k."""
        if k > self.k:
            self.lib.acn_kin_to(self.n_axes, self.s, self._V, self._W, self.k, k, self.Ts, self.q, self._qv)
            self.k = k

    def _aid(self, k: int, axis: int, i: int, z: float, var: float) -> None:
        """Propagate to sample k, then the scalar measurement z of state i (0: r, 1: u) with variance var on
        ``axis`` (-1: every axis)."""
        self.lib.acn_kin_aid(self.n_axes, self.s, self._V, self._W, self.k, k, self.Ts, self.q, self._qv, axis, i,
                             z, var)  # fmt: skip
        self.k = max(self.k, k)
        self.aid_k = k

    def rest(self, k: int, sigma: float) -> None:
        self._aid(k, -1, 1, 0.0, sigma * sigma)

    def fix(self, k: int, j: int, z: float, var: float) -> None:
        self._aid(k, j, 0, float(z), float(var))

    def test(self, k: int, level, n: int, leak: float, drift: float, scale: float, sigma: float):
        """Propagate to sample k, then a forward side's test (:meth:`_Decider._test`) of a candidate of n samples at
        ``level`` (a pointer the kernel reads): (v, sd, r, sd of r) per axis, rows of one (4, n_axes) array; then
        the sum over the axes of v^2 / (sd^2 + sigma^2) read as one axis' chi-square (:func:`chi2_equivalent`), the
        level's jump (|level - the filter's level| over the axes beyond 3 sd of the filter's; 0 while it has
        none), |v| over the axes and the rms of the sds: one kernel call (acn_kin_test)."""
        out = np.empty((4, self.n_axes))
        res = self._res
        self.lib.acn_kin_test(self.n_axes, self.s, self._V, self._W, self._A, self.k, k, self.Ts, self.q, self._qv,
                              self.aid_k, level, self._R, n, leak, drift, scale, sigma * sigma,
                              self.ffi.from_buffer("double[]", out), res)  # fmt: skip
        self.k = max(self.k, k)
        return out, res[0], res[1], (res[2], res[3])


LEAK = 0.1  # share of (level change x time since the last aid) allowed as velocity sd (see _Decider._test)
PEAK_POINTS = 128  # points of the way from the last rest at which a candidate's peak speed is taken
LIKE = 10.0  # a candidate up to this many times the median stillness of the proven rests is as still as they
UNLIKE = 0.5  # ... and one far less still, after a move, keeps its level within UNLIKE x level_still
UNLIKE_TELL = 0.5  # ... and is told by a side only within UNLIKE_TELL x tell (see _Decider._tell_bound)
CONFIRM = 2  # a hypothesis is kept when this many candidates after it are consistent with it, with motion between
WITHIN = 6 * CONFIRM  # ... among the next WITHIN candidates
MOTION = 0.2  # m/s, the speed the body must have reached between two rests for them to test each other
STRIDE = 1.0  # m/s, ... and where the record lost the rests it had before the hypothesis
MARK_EVERY = 4  # a pass after the first resumes at a mark left at every this many candidates' tests (forward) ...
MARKS = 128  # ... or sparser, so that no more marks than this are kept: each holds a copy of the accepted set and the
# proven stillness, so marks at every 4th of 60 000 candidates (a 1e7-sample drive) held 4.4 GB; any mark before the
# first new veto resumes to the same verdicts, a sparser one only replays more

ACCEPT_REASONS = ("consistent", "still start", "still stand", "gate off")
REFUSE_REASONS = ("moving", "level jumped", "cannot tell", "no deceleration")


@dataclass(frozen=True)
class RestDecision:
    """The verdict on one candidate rest [start, stop), the evidence that decided it, and its statistics."""

    start: int
    stop: int
    accepted: bool
    reason: str  # one of ACCEPT_REASONS or REFUSE_REASONS
    evidence: str  # in words: what decided (e.g. "fixes imply 14.6 +/- 0.3 m/s (the fix at 120.0 s)")
    still: float  # mean over axes of the rest's variance / R
    level: float  # |mean acceleration| over the axes, m/s^2 (the model's bias mean removed)
    v_before: float  # |v| over the axes from the filter before it, m/s (NaN: not computed)
    sd_before: float  # its sd (rms over the axes), m/s
    v_after: float  # the same from the filter after it
    sd_after: float
    chi2: float  # the larger of the two sides' mean over axes of v^2 / (sd^2 + sigma^2)


@dataclass
class _Found:
    """One candidate's state during the passes."""

    reason: str = "cannot tell"
    evidence: str = ""
    before: Side | None = None
    after: Side | None = None


def chi2_equivalent(x: float, dof: int) -> float:
    """The one-degree chi-square value with the upper tail of ``x`` under dof degrees of freedom: the test of
    every axis at once, read on the scale of one axis (9: three sd). The kernel's (acn_chi2_equivalent): the tail
    in closed form and its inverse by Halley's steps on erfc: scipy's gammaincc and erfcinv to 1e-11 (1e-10 where the
    tail is subnormal), at a quarter of their calls' cost (a decision reads a few thousand)."""
    from accelnav.estimate.fastsmooth import _lib

    if int(dof) < 1:
        raise ValueError(f"dof: {dof}; a chi-square has one degree of freedom at least")
    return _lib().lib.acn_chi2_equivalent(float(x), int(dof))


def _median(s: list[float]) -> float:
    """The median of a short sorted list (np.median's own: the mean of the two middle values of an even count),
    without numpy's per-call overhead (the forward filter keeps the proven rests' stillness sorted)."""
    h = len(s) // 2
    return s[h] if len(s) % 2 else (s[h - 1] + s[h]) / 2.0


def _speed(s: Side) -> str:
    v, sd = _norms(s)
    return f"{v:.3g} +/- {sd:.2g} m/s"


def _norms(s: Side | None) -> tuple[float, float]:
    """(|v| over the axes, rms of its sd) of one side; NaN without one."""
    if s is None:
        return math.nan, math.nan
    if s.norms is not None:
        return s.norms
    v, sd = s.v.tolist(), s.sd.tolist()
    return math.sqrt(sum(x * x for x in v)), math.sqrt(sum(x * x for x in sd) / len(sd))


def _events(cands: list[Candidate], fixes, n: int, reverse: bool) -> list[tuple]:
    """(sample, order, kind, payload) of one direction, sorted: a candidate's test before anything at its
    first sample, its end (where an accepted rest's second update goes) at its last."""
    ev = []
    for i, c in enumerate(cands):
        a, e = (n - c.stop, n - 1 - c.start) if reverse else (c.start, c.stop - 1)
        ev.append((a, 0, "test", i))
        ev.append((e, 2, "end", i))
    for j, fx in enumerate(fixes):
        for m in fx:
            ev.append((n - 1 - m.k if reverse else m.k, 1, "fix", (j, m.z, m.R, m.k)))
    ev.sort(key=lambda e: (e[0], e[1]))
    return ev


class _Lazy:
    """f(*args), computed on the first look at one of its items (a candidate's peak speed: most verdicts never
    need it)."""

    __slots__ = ("f", "args", "value")

    def __init__(self, f, *args):
        self.f, self.args, self.value = f, args, None

    def __getitem__(self, i):
        if self.value is None:
            self.value = self.f(*self.args)
        return self.value[i]


class _Decider:
    def __init__(self, x, R, Ts, cands, fixes, p, t, start_sd: float = 0.0):
        self.start_sd = start_sd  # the model's prior sd of the start speed: a still start only when it is small
        self.x, self.R, self.Ts, self.cands, self.p, self.t = x, R, Ts, cands, p, t
        self.n = len(x)
        self.fixes = fixes
        self.q = p.level_walk**2
        self.fwd_events = _events(cands, fixes, self.n, False)
        self.bwd_events = _events(cands, fixes, self.n, True)
        self.veto: dict[int, str] = {}  # withdrawn: why
        self._sources: dict[tuple[str, int], str] = {}  # the words naming each aid (_source)
        self._bwd = None  # the backward events as the kernel reads them (backward)
        self._pk = None  # the record's sums and an output as the peak's kernel reads them (_peak)
        self._lv = None  # each candidate's level as the kernels read it (_test)
        # the forward filter's marks, {candidate: (event index of its test, filter, state)} made at each test with no
        # hypothesis open, its last pass's verdicts and the vetoes that pass saw (forward)
        self._marks: dict[int, tuple] = {}
        self._mark_every = max(MARK_EVERY, -(-len(cands) // MARKS))
        self._found: list[_Found] = []
        self._seen_veto: dict[int, str] = {}
        self._start: dict[bool, _Kinematic] = {}  # per direction (reversed?), the filter before any event

    def _fresh(self, reverse: bool) -> _Kinematic:
        """A filter at the start of one direction of time: its sums over the record made once, every pass
        starting from a copy."""
        if reverse not in self._start:
            self._start[reverse] = _Kinematic(self.x, self.Ts, self.R, self.q, reverse)
        return self._start[reverse].copy()

    def _source(self, kind: str, at: int) -> str:
        """The words naming an aid (the fix at sample ``at``, the rest of candidate ``at``), made once per decision:
        every pass names the same aids again."""
        key = (kind, at)
        words = self._sources.get(key)
        if words is None:
            t = self.t
            if kind == "fix":
                words = f"the fix at {t[at]:.2f} s"
            else:
                c = self.cands[at]
                words = f"the rest at {t[c.start]:.2f}-{t[c.stop - 1]:.2f} s"
            self._sources[key] = words
        return words

    def _tells(self, s: Side, tell: float | None = None) -> bool:
        """Every axis' sd within ``tell`` (default: the parameter's; a NaN never is), on floats: cheaper than numpy's
        overhead."""
        tell = self.p.tell if tell is None else tell
        return all(sd <= tell for sd in s.sd.tolist())

    def _tell_bound(self, c: Candidate, like: bool) -> float:
        """The sd a side must reach to call a candidate consistent: ``tell``, or UNLIKE_TELL x ``tell`` for one far
        less still than the record's proven rests and shorter than a stand (``start_s``). Such a piece is a moment of
        a body that moves (a trunk mid-stride) unless the velocity is known well: a lower back walking reads 20-120
        R in its quietest tenth of a second against 1-2 R standing, and mobgap's MS_001 trial 1 (levelled by
        accelnav.level at its standings) accepted a 0.19 s piece at 94 R mid-walk on a side of 0.86 +/- 0.37 m/s,
        which then refused the standing after the walk as moving. A stand's length keeps ``tell``: a stop with a
        knock in it, or an idling engine, is unsteady but long."""
        short = (c.stop - c.start) * self.Ts < self.p.start_s
        return UNLIKE_TELL * self.p.tell if short and not like else self.p.tell

    def forward(self) -> tuple[list[_Found], set[int]]:
        """The forward filter, deciding online; returns every candidate's state and the accepted set.

        Where nothing can tell (no fix, no rest yet), a candidate may be taken as a *hypothesis*: it is kept
        when the next ``CONFIRM`` candidates, tested with it, are consistent and the body moved between
        (a walk's stances: each closes the velocity of the stride before it); when one of them is found
        moving, or cannot be told, the filter goes back to before the hypothesis and goes on without it."""
        p, cands, Ts, t = self.p, self.cands, self.Ts, self.t
        e, kin, st, found = self._resume()
        pending = None  # (hypothesis i, event index of its test, saved kinematics and state, confirmations)
        tried: set[int] = set()  # hypotheses already refuted in this pass
        ev = self.fwd_events
        while e < len(ev) or pending is not None:
            if e == len(ev):  # the record ended before the hypothesis was borne out: on without it
                h, e_h, (kin, st), _, _ = pending
                st = {**st, "acc": set(st["acc"]), "proven": list(st["proven"])}
                tried.add(h)
                found[h].reason = "cannot tell"
                found[h].evidence += "; not borne out: too few candidates after it"
                pending, e = None, e_h
                continue
            k, _, kind, pay = ev[e]
            e += 1
            if kind == "fix":
                j, z, var, _ = pay
                kin.fix(k, j, z, var)
                st["source"], st["fix"] = self._source("fix", k), True
                continue
            i = pay
            c = cands[i]
            acc = st["acc"]
            if kind == "test" and pending is None and i % self._mark_every == 0:
                # a mark: the filter and its state as they stand before the test (no hypothesis open: nothing after
                # it goes back before it), the last visit's kept
                self._marks[i] = (e - 1, kin.copy(), {**st, "acc": set(acc), "proven": list(st["proven"])})
            if kind == "end":
                if i in acc:
                    kin.rest(k, p.sigma)
                    X = kin.X  # a copy: its columns are the rest's own
                    st["last_end"] = (k, X[:, 1].copy(), X[:, 2].copy())
                    if (c.stop - c.start) * Ts >= p.start_s:  # a stand: what a stop's kinematics start from
                        st["last_stand"] = st["last_end"]
                    st["source"] = self._source("rest", i)
                continue
            jump, s = self._test(kin, k, i, st)
            f = found[i]
            f.before, f.evidence = s, ""
            moved = _Lazy(self._peak, c, st["last_end"]) if st["last_end"] is not None else (0.0, 0.0, 0.0)
            f.reason, f.evidence = self._judge(i, c, s, st, moved, jump)
            if pending is not None:
                h, e_h, saved, count, seen = pending
                seen += 1
                if f.reason in REFUSE_REASONS or seen > WITHIN:  # it fails: back to before it, on without it
                    tried.add(h)
                    kin, st = saved
                    st = {**st, "acc": set(st["acc"]), "proven": list(st["proven"])}
                    found[h].reason = "level jumped" if found[h].reason == "consistent" else "cannot tell"
                    found[h].evidence += (
                        f"; not borne out: the candidate at {t[c.start]:.2f} s {f.reason} with it"
                        if f.reason in REFUSE_REASONS
                        else f"; not borne out by the next {WITHIN} candidates"
                    )
                    pending, e = None, e_h
                    continue
                # before the first rest, or for a level that moved, a move; where the record lost a rest it had,
                # a stride's (a car's cruise pieces close on each other after small changes of speed)
                lost = saved[1]["last_end"] is not None and found[h].reason != "consistent"
                if moved[0] >= (STRIDE if lost else MOTION):
                    count += 1
                pending = (h, e_h, saved, count, seen)
                if count >= CONFIRM:
                    found[h].evidence = (
                        f"{found[h].evidence}; borne out by the next {CONFIRM} (the body moved between)"
                        if found[h].reason == "consistent"
                        else f"closes the velocity of the next {CONFIRM} (the body moved between; "
                        f"{found[h].evidence.split(';')[0]})"
                    )
                    found[h].reason = "consistent"
                    pending = None
            elif (
                pending is None
                and i not in tried
                and p.gate > 0
                and (f.reason == "cannot tell" or (f.reason == "consistent" and jump > p.level_still))
            ):
                # a hypothesis (nothing could tell it, or its level moved far: a foot that turned, or a push held),
                # saved as the filter stands before it
                pending = (i, e, (kin.copy(), {**st, "acc": set(acc), "proven": list(st["proven"])}), 0, 0)
                if f.reason == "consistent":
                    f.evidence += f"; its level moved {jump:.2g} m/s^2"
                else:
                    f.reason = "hypothesis"
            if f.reason in ACCEPT_REASONS or f.reason == "hypothesis":
                acc.add(i)
                kin.rest(k, p.sigma)
        return found, st["acc"]

    def _resume(self) -> tuple[int, _Kinematic, dict, list[_Found]]:
        """Where the forward filter starts: (event index, filter, state, verdicts). A pass after the first decides as
        the last did up to the first candidate whose veto is new: it resumes at the last mark before it, the
        verdicts before the mark kept; the first pass, at the record's start."""
        kin = self._fresh(False)
        self.V = kin.V
        found = [_Found() for _ in self.cands]
        st = {"acc": set(), "source": "no aid", "fix": False, "last_end": None, "last_stand": None, "proven": []}
        e = 0
        first = min((i for i, why in self.veto.items() if self._seen_veto.get(i) != why), default=len(self.cands))
        resume = max((i for i in self._marks if i <= first), default=None)
        self._seen_veto = dict(self.veto)
        if resume is None:
            self._marks = {}
        else:
            e, saved_kin, saved_st = self._marks[resume]
            kin, st = saved_kin.copy(), {**saved_st, "acc": set(saved_st["acc"]), "proven": list(saved_st["proven"])}
            found[:resume] = [_Found(f.reason, f.evidence, f.before) for f in self._found[:resume]]
            self._marks = {i: m for i, m in self._marks.items() if i <= resume}
        self._found = found
        return e, kin, st, found

    def _judge(self, i: int, c: Candidate, s: Side, st: dict, moved, jump: float) -> tuple[str, str]:
        """(reason, evidence) of candidate i from the forward side ``s`` and the other lines of evidence."""
        p = self.p
        # a level may move far after a move (a foot turns, a mount tilts) in a candidate as still as the record's
        # proven rests; one far less still (a push held, a braking) keeps the level of a body that did not turn
        like = not st["proven"] or c.still <= max(p.still_k, LIKE * _median(st["proven"]))
        if p.gate == 0:
            return "gate off", "every candidate accepted (gate 0)"
        if i in self.veto:
            return "moving", self.veto[i]
        # the bound on the level's jump depends on the motion since the last rest: looked at only when the jump
        # could exceed one of its values (the peak speed is the costliest figure here)
        options = (p.level_max, p.level_still) if like else (UNLIKE * p.level_still, p.level_still)
        if jump <= min(options):
            allowed = math.inf
        elif like:
            allowed = p.level_max if moved[0] >= MOTION else p.level_still
        else:  # the motion seen with the rest's own level (the candidate's, a push's, would hide it)
            allowed = UNLIKE * p.level_still if moved[2] >= MOTION else p.level_still
        if jump > allowed:
            return "level jumped", f"level {jump:.2g} m/s^2 off the last rest's, more than {allowed:g} with " + (
                ("motion between" if like else f"motion between, at {c.still:.2g} R: less still than the rests")
                if moved[0] >= MOTION
                else f"no motion between (peak {moved[0]:.2g} m/s)"
            )
        if s.chi2 > p.gate:
            what = "fixes imply" if s.fix and st["source"].startswith("the fix") else "v"
            return "moving", f"{what} {_speed(s)} before it (from {s.source})"
        bound = self._tell_bound(c, like)
        if self._tells(s, bound):
            bisect.insort(st["proven"], c.still)
            return "consistent", f"v {_speed(s)} before it (from {s.source})"
        stand = _Lazy(self._peak, c, st["last_stand"]) if st["last_stand"] is not None else moved
        reason, evidence = self._other_evidence(c, s, st["last_end"], st["proven"], st["fix"], stand)
        if bound < p.tell and self._tells(s):
            evidence += (
                f"; at {c.still:.2g} R, far less still than the proven rests and shorter than a stand: told only "
                f"within {bound:g} m/s"
            )
        if reason == "still start":
            bisect.insort(st["proven"], c.still)
        return reason, evidence

    def _test(self, kin: _Kinematic, k: int, i: int, st: dict) -> tuple[float, Side]:
        """The forward filter taken to candidate i's first sample k: the level's jump there and its side.

        The level's path between the last aid and here is taken as linear; a leak that changed by L since then may
        have changed along any path: up to L D / 2 of velocity, L D / 4 allowed (one sd); and a mean acceleration
        error no level explains (a leak changing within the move): drift D (D the time since the last aid); and
        errors in proportion to the acceleration itself (a scale factor, a level frame turned during a stride: on a
        real foot a stride leaves 0.2-0.8 m/s in the integral): scale x integral of |x| since the last aid. The
        position is widened likewise, by the velocity's widening over D. Over the axes: the sum, as the
        chi-square of one axis with the same tail (chi2_equivalent): a move along one axis is not diluted by the
        others' rest, and three quiet axes do not add up to a move (acn_kin_test, acn_kin_side)."""
        p, c = self.p, self.cands[i]
        if self._lv is None:  # each candidate's level as the kernel reads it, made once per decision
            self._lv = [kin.ffi.from_buffer("double[]", np.ascontiguousarray(d.level, dtype=np.float64))
                        for d in self.cands]  # fmt: skip
        out, chi2, jump, norms = kin.test(k, self._lv[i], c.stop - c.start, LEAK, p.drift, p.scale, p.sigma)
        return jump, _made(out[0], out[1], chi2, st["source"], st["fix"], out[2], out[3], norms)

    def _peak(self, c: Candidate, last_end) -> tuple[float, float, float]:
        """(peak, end) speed integrated from the last rest's end to the candidate's start, the level linear
        from the rest's to the candidate's, and the peak with the rest's level kept; the peaks on at most
        PEAK_POINTS points of the way (a cost per candidate that does not grow with the time since the rest), by the
        kernel (acn_kin_peak)."""
        if self._pk is None or self._pk[0] is not self.V:  # the kernel's pointers, made once per decision
            from accelnav.estimate.fastsmooth import _lib

            mod = _lib()
            self._pk = (self.V, mod.lib, mod.ffi.from_buffer, mod.ffi.from_buffer("double[]", self.V),
                        mod.ffi.new("double[3]"))  # fmt: skip
        _, lib, buf, V, out = self._pk  # row vectors, contiguous (from_buffer refuses any other)
        e, u0, e0 = last_end
        a = max(c.start, e)
        num = min(a - e + 1, PEAK_POINTS)
        lib.acn_kin_peak(len(u0), V, self.Ts, e, a, num, buf("double[]", u0), buf("double[]", e0),
                               buf("double[]", c.level), out)  # fmt: skip
        # the square root taken of the peak's square (it keeps the order)
        return math.sqrt(out[0]), math.sqrt(out[1]), math.sqrt(out[2])

    def _other_evidence(self, c: Candidate, s: Side, last_end, proven: list[float], fix_seen: bool, moved):
        p, Ts = self.p, self.Ts
        sd = float(s.sd.max())  # np.max's value (a NaN kept) without its wrapper
        dur = (c.stop - c.start) * Ts
        cannot = f"cannot tell: sd of v {sd:.2g} m/s before it ({'fixes too far' if fix_seen else 'no fix'})"
        if last_end is None:
            if self.start_sd > p.tell:
                return (
                    "cannot tell",
                    cannot + f", no rest before (the model lets the run start at {self.start_sd:.3g} m/s)",
                )
            if c.start * Ts <= p.start_within_s and dur >= p.start_s and c.still <= p.still_k:
                return "still start", (
                    f"still start: {dur:.2f} s at {c.still:.2g} R from {c.start * Ts:.2f} s "
                    "(assumed: the run starts at rest)"
                )
            return "cannot tell", cannot + ", no rest before"
        bound = max(p.still_k, 2.0 * _median(proven)) if proven else p.still_k
        if dur < p.start_s or c.still > bound:
            return "cannot tell", cannot + f"; {dur:.2f} s at {c.still:.2g} R is not a stand (still <= {bound:.2g} R)"
        # the kinematics of a stop: the velocity since the last rest, its level linear to this one's
        peak, end = moved[:2]
        if end <= p.rel * peak and peak >= 2.0 * sd:  # a deceleration, and one the uncertainty cannot explain
            return "still stand", (
                f"still stand: {dur:.2f} s at {c.still:.2g} R; speed since the last stand {end:.2g} m/s after a "
                f"peak of {peak:.3g} m/s ({cannot})"
            )
        return "no deceleration", (
            f"quiet at {c.still:.2g} R but no deceleration: speed since the last stand {end:.3g} m/s, "
            f"peak {peak:.3g} m/s (a stop needs <= {p.rel:g} of a peak >= 2 sd; {cannot})"
        )

    def backward(self, acc: set[int]) -> list[Side | None]:
        """The backward filter with the accepted set ``acc``: every candidate's side after it. It decides nothing
        (the sides are read after it): its whole run over the events is the kernel's (acn_kin_backward), the words
        naming each side's aid made here."""
        p, cands, n = self.p, self.cands, self.n
        kin = self._fresh(True)
        ffi, m, n_axes = kin.ffi, len(cands), kin.n_axes
        if self._bwd is None:  # the events as arrays, and each candidate's level and length: once per decision
            ev = self.bwd_events
            kinds = {"test": 0, "fix": 1, "end": 2}
            self._bwd = (
                np.array([e[0] for e in ev], dtype=np.int64),
                np.array([kinds[e[2]] for e in ev], dtype=np.intc),
                np.array([e[3][0] if e[2] == "fix" else e[3] for e in ev], dtype=np.int64),
                np.array([e[3][1] if e[2] == "fix" else 0.0 for e in ev], dtype=np.float64),
                np.array([e[3][2] if e[2] == "fix" else 0.0 for e in ev], dtype=np.float64),
                np.array([c.level for c in cands], dtype=np.float64).reshape(m, n_axes),
                np.array([c.stop - c.start for c in cands], dtype=np.int64),
            )
        ev_k, ev_kind, ev_i, ev_z, ev_var, level, length = self._bwd
        accm = np.zeros(m, dtype=np.uint8)
        accm[sorted(acc)] = 1
        sides = np.full((m, 4, n_axes), np.nan)
        total = np.full(m, np.nan)
        aid = np.full(m, -1, dtype=np.int64)
        fix = np.zeros(m, dtype=np.uint8)
        buf = ffi.from_buffer
        kin.lib.acn_kin_backward(
            n_axes, kin.s, kin._V, kin._W, kin._A, kin.Ts, kin.q, kin._qv, kin._R, len(ev_k), buf("long[]", ev_k),
            buf("int[]", ev_kind), buf("long[]", ev_i), buf("double[]", ev_z), buf("double[]", ev_var),
            buf("unsigned char[]", accm), buf("double[]", level), buf("long[]", length), LEAK, p.drift, p.scale,
            p.sigma, buf("double[]", sides), buf("double[]", total), buf("long[]", aid), buf("unsigned char[]", fix),
        )  # fmt: skip
        out: list[Side | None] = []
        chi2 = kin.lib.acn_chi2_equivalent
        for s, tot, e, f in zip(sides, total.tolist(), aid.tolist(), fix.tolist(), strict=True):  # each tested once
            if e < 0:
                source = "no aid"
            else:
                _, _, kind, pay = self.bwd_events[e]
                source = self._source("fix", pay[3]) if kind == "fix" else self._source("rest", pay)
            out.append(_made(s[0], s[1], chi2(tot, n_axes), source, bool(f), s[2], s[3], None))
        assert n == len(self.x)
        return out

    def run(self) -> tuple[list[_Found], set[int]]:
        p = self.p
        for pass_no in range(p.passes + 1):
            found, acc = self.forward()
            after = self.backward(acc)
            for f, s in zip(found, after, strict=True):
                f.after = s
            if p.gate == 0:
                return found, acc
            # each accepted rest against the other side, and against the positions both sides give it
            score = {i: max(after[i].chi2, self._gap(found[i].before, after[i], self.cands[i])) for i in acc}
            bad = sorted(i for i in acc if score[i] > p.gate)
            shorts = self._short_before_stands(found, acc)
            if not bad and not shorts:
                return found, acc
            for j, i in shorts.items():  # a short rest that makes a stand after it "move" gives way to it
                self.veto[j] = f"contradicts the stand at {self.t[self.cands[i].start]:.2f} s, longer and still"
            if pass_no == p.passes:  # out of passes: what still disagrees leaves, nothing is added
                for i in bad:
                    self._withdraw(i, after[i], found[i].before)
                found, acc = self.forward()
                after = self.backward(acc)
                for f, s in zip(found, after, strict=True):
                    f.after = s
                return found, acc
            # the worst of each run of consecutive disagreeing accepted rests leaves: its neighbours may
            # only have disagreed through it
            order = sorted(acc)
            pos = {i: r for r, i in enumerate(order)}
            group: list[int] = []
            for i in bad + [None]:
                if i is not None and (not group or pos[i] == pos[group[-1]] + 1):
                    group.append(i)
                    continue
                if group:
                    worst = max(group, key=lambda g: score[g])
                    gapped = score[worst] > after[worst].chi2  # refuted by the positions: by the fixes
                    # the rest after it that the disagreement came from may be the false one: of the two, the
                    # shorter gives way (a ramp's quiet piece beside a stop)
                    nxt = pos[worst] + 1
                    if not gapped and nxt < len(order) and after[worst].source.startswith("the rest"):
                        j = order[nxt]
                        c, cj = self.cands[worst], self.cands[j]
                        # of the two, the one with less evidence of its own (its other side, or its stillness)
                        # gives way; on a tie the shorter
                        mine = self._support(c, found[worst].before, found[worst].reason)
                        theirs = self._support(cj, after[j], found[j].reason)
                        if (theirs, cj.stop - cj.start) < (mine, c.stop - c.start):
                            self.veto[j] = f"contradicts the rest at {self.t[c.start]:.2f} s, which has more evidence"
                            worst = None
                    if worst is not None:
                        self._withdraw(worst, after[worst], found[worst].before)
                        # where a fix refuted it, the pieces it touches, nothing between (a gap under a window),
                        # fall with it: a ramp cut into quiet pieces must not survive one piece at a time (a piece
                        # the other rests refuted may be the end of a stance whose other piece is sound)
                        by_fix = after[worst].source.startswith("the fix") or gapped
                        for step in (-1, 1) if by_fix else ():
                            r = pos[worst]
                            while 0 <= r + step < len(order) and self._touch(order[min(r, r + step)],
                                                                             order[max(r, r + step)]):  # fmt: skip
                                r += step
                                j = order[r]
                                self.veto.setdefault(j, f"touches the rest at {self.t[self.cands[worst].start]:.2f} s, "
                                                        f"withdrawn: {self.veto[worst]}")  # fmt: skip
                group = [i] if i is not None else []
        return found, acc

    def _touch(self, i: int, j: int) -> bool:
        """Candidates i < j are pieces of one stretch: less than a window (``bridge_s``) between them."""
        return (self.cands[j].start - self.cands[i].stop) * self.Ts <= max(self.p.bridge_s, 2 * self.Ts)

    def _short_before_stands(self, found: list[_Found], acc: set[int]) -> dict[int, int]:
        """{j: i}: accepted rests j shorter than a stand (``start_s``) that were all that made the stand i after
        them "moving" (a stand: ``start_s`` long, still at the sensor's noise)."""
        p, out = self.p, {}
        order = sorted(acc)
        stops = [self.cands[j].stop for j in order]
        monotone = all(a <= b for a, b in zip(stops, stops[1:], strict=False))  # the detector's spans: in order
        for i, f in enumerate(found):
            c = self.cands[i]
            if f.reason != "moving" or i in self.veto or f.before is None or not f.before.source.startswith("the rest"):
                continue
            if (c.stop - c.start) * self.Ts < p.start_s or c.still > p.still_k:
                continue
            j = self._last_before(order, stops if monotone else None, c.start)
            if j is not None and (self.cands[j].stop - self.cands[j].start) * self.Ts < p.start_s:
                out.setdefault(j, i)
        return out

    def _last_before(self, order: list[int], stops: list[int] | None, k: int) -> int | None:
        """The last of the accepted rests ``order`` (sorted) that ends by sample k; None: none does. ``stops``: their
        ends when sorted (the detector's spans come in time order), bisected; None: each looked at."""
        if stops is not None:
            n = bisect.bisect_right(stops, k)
            return order[n - 1] if n else None
        before = [j for j in order if self.cands[j].stop <= k]
        return before[-1] if before else None

    def _support(self, c: Candidate, other: Side | None, reason: str) -> int:
        """1 when a candidate has evidence besides the rest it disagrees with: a side that tells and agrees,
        or the stillness of a still start or stand."""
        told = other is not None and self._tells(other) and other.chi2 <= self.p.gate
        return int(told or reason in ("still start", "still stand"))

    def _gap(self, before: Side | None, after: Side | None, c: Candidate) -> float:
        """How far apart the positions of the two sides are, for a body that stood still between them: the
        forward filter's at the candidate's start (the fixes and rests before it) against the backward one's at
        its end (those after it), their sds and the rest's own sigma over its length; as the chi-square of one
        axis (:func:`chi2_equivalent`). Two sides that know the position only through the fixes and the other
        rests: a quiet stretch at cruise between two fixes is refuted by the distance they put between its
        ends, whatever its velocity looks like from either side alone (a diffuse side gives 0)."""
        if before is None or after is None or before.r is None or after.r is None:
            return 0.0
        if not (before.fix and after.fix):
            return 0.0
        own = self.p.sigma * (c.stop - c.start) * self.Ts
        d = after.r - before.r
        return chi2_equivalent(float(np.sum(d * d / (before.r_sd**2 + after.r_sd**2 + own * own))), len(d))

    def _withdraw(self, i: int, s: Side, before: Side | None = None) -> None:
        c = self.cands[i]
        if s.chi2 < self._gap(before, s, c):
            moved = float(np.linalg.norm(s.r - before.r))
            self.veto[i] = (
                f"fixes imply it moved {moved:.3g} m during it (position from {before.source} before it, "
                f"from {s.source} after it)"
            )
            return
        what = "fixes imply" if s.fix and s.source.startswith("the fix") else "v"
        self.veto[i] = f"{what} {_speed(s)} after it (from {s.source})"


def _candidates(x, ok, R, spans) -> list[Candidate]:
    """Each span [a, b) (non-empty, within the record) as a candidate: over its samples where every axis is ``ok``,
    the mean acceleration and the mean over axes of its variance / R (none usable: level 0; one or none: variance
    R). The kernel's sums (acn_kin_cands) run in numpy's order over axis 0: a mean and variance of each span
    without numpy's per-call overhead, which cost more than the sums."""
    from accelnav.estimate.fastsmooth import _lib

    n, n_axes = x.shape
    starts = np.array([a for a, _ in spans], dtype=np.int64).reshape(-1)
    stops = np.array([b for _, b in spans], dtype=np.int64).reshape(-1)
    if np.any(starts < 0) or np.any(stops <= starts) or np.any(stops > n):
        raise ValueError(f"spans: each [a, b) must be non-empty and lie within the record's {n} samples")
    mod = _lib()
    ffi = mod.ffi
    x = np.ascontiguousarray(x, dtype=np.float64)
    usable = np.ascontiguousarray(ok.all(axis=1), dtype=np.uint8)
    R = np.ascontiguousarray(R, dtype=np.float64)
    level = np.zeros((len(starts), n_axes))
    still = np.zeros(len(starts))
    if len(starts):
        mod.lib.acn_kin_cands(
            n_axes, ffi.from_buffer("double[]", x), ffi.from_buffer("unsigned char[]", usable), len(starts),
            ffi.from_buffer("long[]", starts), ffi.from_buffer("long[]", stops), ffi.from_buffer("double[]", R),
            ffi.from_buffer("double[]", level), ffi.from_buffer("double[]", still),
        )  # fmt: skip
    return [Candidate(int(a), int(b), lv, float(s)) for a, b, lv, s in zip(starts, stops, level, still, strict=True)]


def decide(x, ok, R, Ts: float, t: np.ndarray, spans, fixes, p, start_sd: float = 0.0) -> list[RestDecision]:
    """The decision on every candidate span [a, b) of ``spans`` (see the module docstring). ``x`` (N, n_axes):
    acceleration less the model's bias mean (0 where not ``ok``); ``fixes``: per axis column a list of
    position-fix measurements (accelnav.estimate.kf) or None."""
    n_axes = x.shape[1]
    fixes = [[] for _ in range(n_axes)] if fixes is None else [list(f) for f in fixes]
    if len(fixes) != n_axes:
        raise ValueError(f"fixes: {len(fixes)} axes given; the run has {n_axes}")
    # the kernels read the record's sums at these samples and R per axis: anything outside is refused here
    if np.shape(R) != (n_axes,):
        raise ValueError(f"R: shape {np.shape(R)}; the run has {n_axes} axes")
    outside = [m.k for f in fixes for m in f if not 0 <= m.k < len(x)]
    if outside:
        raise ValueError(f"fixes: sample {outside[0]} outside the record's {len(x)} samples")
    cands = _candidates(x, ok, R, spans)
    dec = _Decider(x, R, Ts, cands, fixes, p, t, start_sd)
    found, acc = dec.run()
    out = []
    nan = float("nan")
    for i, (c, f) in enumerate(zip(cands, found, strict=True)):
        b, a = f.before, f.after
        ev = f.evidence
        if f.reason == "consistent" and a is not None and not ev:
            ev = f"v {_speed(a)} after it (from {a.source})"
        elif f.reason == "consistent" and a is not None:
            ev += f"; {_speed(a)} after it (from {a.source})"
        vb, sb = _norms(b)
        va, sa = _norms(a)
        chi2 = max(s.chi2 for s in (b, a) if s is not None) if (b or a) else nan
        out.append(
            RestDecision(c.start, c.stop, i in acc, f.reason, ev, c.still, float(np.linalg.norm(c.level)), vb, sb, va,
                         sa, chi2)
        )  # fmt: skip
    return out
