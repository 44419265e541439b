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
both whole in C beside the smoother's kernels (csrc/fastsmooth.c: acn_kin_forward decides online, with the
filter, one saved copy for a hypothesis' replay and the marks; acn_kin_backward gives the sides after; the
chi-square's tail, each candidate's statistics and peak speed). The forward kernel says of each verdict a reason,
the kind of its evidence and its figures; the words are made here, and only when read (:meth:`_Decider._words`,
the same words the Python filter it replaced wrote: tests/estimate/test_rest_decision_same.py). What is left in
Python per pass is the re-test of the accepted rests and the withdrawals (:meth:`_Decider.run`), a few
microseconds per candidate: per sample the cost grows with the density of candidates and with the passes, not
with the record's length. A pass after the first runs the forward filter again only from the first candidate
whose veto is new (it resumes at a mark the last pass left before that candidate's test: before it, nothing
differs; a mark holds the filter only, the accepted set and the proven stillness before it are the kept
verdicts'), the backward filter from the start (bench/speed/bench_rest_decision.py measures it beside the plain
smoother and beside the numpy filter of the first version).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
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


@dataclass(frozen=True, slots=True)
class Candidate:
    start: int
    stop: int
    level: np.ndarray  # (n_axes,) mean acceleration (model's bias mean removed), m/s^2
    still: float  # mean over axes of its variance / R


class _Kinematic:
    """The kinematic filter of the module docstring over one direction of time of one record.

    The axes do not couple: each holds its state (r, u, e) and the six entries of its symmetric covariance, 9
    doubles [r, u, e, Prr, Pru, Pre, Puu, Pue, Pee], in one C buffer; the record's sums it reads (V, A, W below) are
    read by the kernels at the samples they need, from checkpoints made here once (:data:`SUMS_EVERY`), every run
    over the events (acn_kin_forward, acn_kin_backward in csrc/fastsmooth.c) starting from a copy. A
    decision makes a few hundred small steps per pass, each a few dozen multiplications per axis: Python's own
    per-step overhead cost more than the arithmetic (bench/speed/bench_rest_decision.py)."""

    def __init__(self, x: np.ndarray, Ts: float, R: np.ndarray, q: float, reverse: bool = False):
        """The filter before any event on the record ``x`` (N, n_axes), its rows last first when ``reverse``."""
        from accelnav.estimate.fastsmooth import _lib  # the kernels (not loaded at the package's import)

        mod = _lib()
        self.ffi, self.lib = mod.ffi, mod.lib
        n, self.n_axes = x.shape
        self.Ts, self.q = Ts, q
        # V[k] = Ts sum_{i<k} x[i]; A[k] = Ts sum_{i<k} |x[i]|: how much moved; W[k] = Ts sum_{i<k} V[i]; numpy's
        # cumsums' order (acn_kin_sums). Not held: 48 B a sample at 2 axes each way, 960 MB of a 1e7-sample record's
        # 1.57 GB peak. The kernels read a sample's row summed on from the checkpoint or the row they read last
        # before it (acn_kin_rec), step by step as acn_kin_sums sums: the same doubles (test_rest_sums.py)
        if self.n_axes > KIN_MAX_AXES:
            raise ValueError(f"rest decision: {self.n_axes} axes; accepted: at most {KIN_MAX_AXES}")
        self.x = np.ascontiguousarray(x, dtype=np.float64)  # the kernels read it through rec
        self.cp = np.empty((n // SUMS_EVERY + 1, 3 * self.n_axes))
        self.rec = self.ffi.new("acn_kin_rec *")
        self._x = self.ffi.from_buffer("double[]", self.x)
        self.rec.n, self.rec.n_axes, self.rec.x, self.rec.reverse = n, self.n_axes, self._x, bool(reverse)
        self.rec.Ts, self.rec.every = Ts, SUMS_EVERY
        self._cp = self.ffi.from_buffer("double[]", self.cp)
        if self.lib.acn_kin_checkpoints(self.rec, self._cp) != 0:
            raise ValueError("rest decision: the record's sums were refused by the kernel (axes, length or spacing)")
        self.R = np.ascontiguousarray(R, dtype=np.float64)
        self.qv = self.R * Ts
        # the kernels read these through pointers made once (the arrays are kept alive beside them)
        self._R, self._qv = (self.ffi.from_buffer("double[]", a) for a in (self.R, self.qv))
        self.s = self.ffi.new("double[]", [v for _ in range(self.n_axes) for v in (0.0, 0.0, 0.0, DIFFUSE[0],
                                           0.0, 0.0, DIFFUSE[1], 0.0, DIFFUSE[2])])  # fmt: skip
        self.k = 0
        self.aid_k = 0  # sample of the last aid

    def copy(self) -> _Kinematic:
        new = object.__new__(_Kinematic)
        new.__dict__.update(self.__dict__)
        new.s = self.ffi.new("double[]", 9 * self.n_axes)
        self.ffi.memmove(new.s, self.s, self.ffi.sizeof(self.s))
        return new


SUMS_EVERY = 256  # the decision's sums kept at every this many samples (3 n_axes doubles each, both ways: 3.75 MB for
# a 1e7-sample record at 2 axes, for 960 MB whole); a read sums on at most this many rows, or from the row read last
KIN_MAX_AXES = 8  # acn_kin_rec holds a row of at most 8 axes
LEAK = 0.1  # share of (level change x time since the last aid) allowed as velocity sd (fastsmooth.c kin_side)
PEAK_POINTS = 128  # points of the way from the last rest at which a candidate's peak speed is taken
LIKE = 10.0  # a candidate up to this many times the median stillness of the proven rests is as still as they
UNLIKE = 0.5  # ... and one far less still, after a move, keeps its level within UNLIKE x level_still
UNLIKE_TELL = 0.5  # ... and, shorter than a stand, is told by a side only within UNLIKE_TELL x tell (acn_kin_forward)
CONFIRM = 2  # a hypothesis is kept when this many candidates after it are consistent with it, with motion between
WITHIN = 6 * CONFIRM  # ... among the next WITHIN candidates
MOTION = 0.2  # m/s, the speed the body must have reached between two rests for them to test each other
STRIDE = 1.0  # m/s, ... and where the record lost the rests it had before the hypothesis
MARK_EVERY = 4  # a pass after the first resumes at a mark left at every this many candidates' tests (forward) ...
MARKS = 128  # ... or sparser, so that no more marks than this are kept (when each held a copy of the accepted set and
# the proven stillness, marks at every 4th of 60 000 candidates, a 1e7-sample drive, held 4.4 GB; now each is the
# filter alone, 13 doubles per axis); any mark before the first new veto resumes to the same verdicts, a sparser one
# only replays more

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


class _Rows:
    """What the verdicts of one :func:`decide` read, shared by all of them: the candidates, the forward pass'
    verdicts and rows (chi2, |v|, sd of the side before), the accepted set, the last backward pass' sides and rows."""

    __slots__ = ("cands", "found", "acc", "after", "before", "behind")

    def __init__(self, cands: _Cands, found: _Found, acc: set[int], after: _Sides | None):
        self.cands, self.found, self.acc, self.after = cands, found, acc, after
        self.before = found._ps.stat
        self.behind = None if after is None else after._rows[1]


def _chi2(r: _Rows, i: int) -> float:
    cb = float(r.before[i, 0])
    return cb if r.behind is None else max(cb, float(r.behind[i, 0]))


def _level_norm(r: _Rows, i: int) -> float:
    lv = r.cands.level[i]  # np.linalg.norm's own sum for a vector (its dot), without its checks
    return math.sqrt(lv.dot(lv))


_READ = {  # each field of a verdict of decide(), read from its rows (_Rows) and its index
    "start": lambda r, i: int(r.cands.start[i]),
    "stop": lambda r, i: int(r.cands.stop[i]),
    "accepted": lambda r, i: i in r.acc,
    "reason": lambda r, i: r.found.reasons[i],
    "still": lambda r, i: float(r.cands.still[i]),
    "level": _level_norm,
    "v_before": lambda r, i: float(r.before[i, 1]),
    "sd_before": lambda r, i: float(r.before[i, 2]),
    "v_after": lambda r, i: math.nan if r.behind is None else float(r.behind[i, 1]),
    "sd_after": lambda r, i: math.nan if r.behind is None else float(r.behind[i, 2]),
    "chi2": _chi2,
}


def _field(name: str) -> property:
    """A field of :class:`_Decided` read from the decision's rows when read; one given to the dataclass' own __init__
    (dataclasses.replace) is kept instead."""
    read = _READ[name]

    def get(self):
        try:
            rows, i = self._rows, self._i
        except AttributeError:  # made by __init__: its own fields
            return self.__dict__[name]
        return read(rows, i)

    def put(self, value) -> None:
        self.__dict__[name] = value

    return property(get, put)


class _Decided(RestDecision):
    """A verdict of :func:`decide` that holds its index into the decision's rows (:class:`_Rows`), its fields read
    from them when read and its evidence in words made when first read: a long record's tens of thousands of verdicts
    are counted, their words read for a few (the same words: :meth:`_Decider._words`). A dict of thirteen fields each
    held 1 kB a verdict, 6 B a sample of a 1e7-sample drive, and cost 0.4 s to fill. Its fields are the rows': a field
    set on it by object.__setattr__ is not read back (dataclasses.replace makes a verdict of its own fields), and a
    pickled verdict carries its decision's rows."""

    __slots__ = ("_rows", "_i")

    start = _field("start")
    stop = _field("stop")
    accepted = _field("accepted")
    reason = _field("reason")
    still = _field("still")
    level = _field("level")
    v_before = _field("v_before")
    sd_before = _field("sd_before")
    v_after = _field("v_after")
    sd_after = _field("sd_after")
    chi2 = _field("chi2")

    @property
    def evidence(self) -> str:
        d = self.__dict__
        ev = d.get("_evidence")
        if ev is None:
            r, i = self._rows, self._i
            ev = d["_evidence"] = _evidence(r.found[i], None if r.after is None else r.after[i])
        return ev

    @evidence.setter
    def evidence(self, words: str) -> None:  # the dataclass' own __init__ (dataclasses.replace)
        self.__dict__["_evidence"] = words


def _evidence(f: _Verdict, after: Side | None) -> str:
    """A verdict's evidence in words: the forward pass's, and for a consistent one the side after it."""
    ev = f.evidence
    if f.reason == "consistent" and after is not None and not ev:
        ev = f"v {_speed(after)} after it (from {after.source})"
    elif f.reason == "consistent" and after is not None:
        ev += f"; {_speed(after)} after it (from {after.source})"
    return ev


class Clock:
    """A record's times on its grid, ``t[k]`` = k Ts as ``np.arange(n) * Ts`` gives them (the same doubles), made for
    the samples read: what :func:`decide` names in its words, without an array of the record's length."""

    def __init__(self, n: int, Ts: float):
        self.n, self.Ts = int(n), float(Ts)

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k):
        if isinstance(k, int | np.integer):  # one sample, as the words read them: no array made
            k = int(k)
            if not -self.n <= k < self.n:
                raise IndexError(f"sample {k}: outside the record's {self.n}")
            return np.float64(k + self.n if k < 0 else k) * self.Ts
        k = np.asarray(k, dtype=np.int64)
        if np.any((k < -self.n) | (k >= self.n)):
            raise IndexError(f"sample {k}: outside the record's {self.n}")
        return np.where(k < 0, k + self.n, k).astype(np.float64)[()] * self.Ts  # [()]: a scalar for one sample


class _TimesAt:
    """The record's times at a few samples (those the words name: the candidates' ends, the fixes), read as ``t[k]``
    is: what the verdicts keep of ``t`` when they make their words later (not the whole record's times)."""

    def __init__(self, t: np.ndarray, at: np.ndarray):
        at = np.asarray(at, dtype=np.int64)
        if np.all(at[1:] >= at[:-1]):  # sorted (the events' samples): its unique values without a sort
            self.k = at[np.concatenate(([True], at[1:] != at[:-1]))] if len(at) else at
        else:
            self.k = np.unique(at)
        self.v = np.asarray(t)[self.k]  # a Clock's times are read from the Clock itself (decide's words.t)

    def __getitem__(self, k: int):
        i = int(np.searchsorted(self.k, k))
        if i == len(self.k) or self.k[i] != k:
            raise IndexError(f"sample {k}: not one whose time was kept")
        return self.v[i]


def chi2_equivalent(x: float, dof: int) -> float:
    """The one-degree chi-square value with the upper tail of ``x`` under dof degrees of freedom: the test of
    every axis at once, read on the scale of one axis (9: three sd). The kernel's (acn_chi2_equivalent): the tail
    in closed form and its inverse by Halley's steps on erfc: scipy's gammaincc and erfcinv to 1e-11 (1e-10 where the
    tail is subnormal), at a quarter of their calls' cost (a decision reads a few thousand)."""
    from accelnav.estimate.fastsmooth import _lib

    if int(dof) < 1:
        raise ValueError(f"dof: {dof}; a chi-square has one degree of freedom at least")
    return _lib().lib.acn_chi2_equivalent(float(x), int(dof))


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


class _Events:
    """One direction's events as the kernels read them, in sample order: a candidate's test (kind 0) before anything
    at its first sample, a fix (1) then, its end (2: where an accepted rest's second update goes) at its last; fixes
    at one sample keep their order. ``k`` the sample in this direction's time, ``i`` the candidate (a fix: its axis),
    ``z`` and ``var`` a fix's measurement (:meth:`at`: its sample in the record's time). Arrays, not a tuple per
    event: a 1e7-sample drive has 60 000 candidates, and the list sorted in Python cost 0.6 s and 2 B a sample held."""

    __slots__ = ("k", "kind", "i", "z", "var", "_n", "_reverse")

    def __init__(self, cands: _Cands, fixes, n: int, reverse: bool):
        m, starts, stops = len(cands), cands.start, cands.stop
        fx = [(j, mm.k, mm.z, mm.R) for j, f in enumerate(fixes) for mm in f]
        fk = np.array([k for _, k, _, _ in fx], dtype=np.int64)
        k = np.empty(2 * m + len(fx), dtype=np.int64)
        k[0 : 2 * m : 2], k[1 : 2 * m : 2] = (n - stops, n - 1 - starts) if reverse else (starts, stops - 1)
        k[2 * m :] = n - 1 - fk if reverse else fk
        kind = np.empty(len(k), dtype=np.intc)
        kind[0 : 2 * m : 2], kind[1 : 2 * m : 2], kind[2 * m :] = 0, 2, 1
        i = np.empty(len(k), dtype=np.int64)
        i[0 : 2 * m : 2] = i[1 : 2 * m : 2] = np.arange(m)
        i[2 * m :] = [j for j, _, _, _ in fx]
        z, var = np.zeros(len(k)), np.zeros(len(k))
        z[2 * m :], var[2 * m :] = [v for _, _, v, _ in fx], [v for _, _, _, v in fx]
        order = np.lexsort((kind, k))  # stable: the order above within one (sample, kind)
        self.k, self.kind, self.i, self.z, self.var = (a[order] for a in (k, kind, i, z, var))
        self._n, self._reverse = n, reverse

    def at(self, e: int) -> int:
        """Event e's sample in the record's time."""
        k = int(self.k[e])
        return self._n - 1 - k if self._reverse else k

    def __len__(self) -> int:
        return len(self.k)


# the kernel's reason codes (acn_kin_forward): the accepted, the refused, a hypothesis still open
_REASONS = (*ACCEPT_REASONS, *REFUSE_REASONS, "hypothesis")
# the kinds of evidence it names (acn_kin_fwd_out.base), in its order
_EV = {k: i for i, k in enumerate(("gate off", "veto", "level", "moving", "consistent", "start sd", "still start",
                                   "no rest", "not stand", "still stand", "no deceleration"))}  # fmt: skip


class _Pass:
    """The forward passes' verdicts as the kernel wrote them (acn_kin_fwd_out, fastsmooth.h), a row per candidate: a
    pass writes the rows from its resume on, the rows before are the verdicts it keeps."""

    FIELDS = (("reason", "int"), ("base", "int"), ("flags", "int"), ("outcome", "int"), ("oarg", "long"),
              ("num", "double"), ("side", "double"), ("stat", "double"), ("aid", "long"),
              ("fix", "unsigned char"))  # fmt: skip

    def __init__(self, m: int, n_axes: int):
        m = max(m, 1)
        self.reason, self.base, self.flags, self.outcome = (np.zeros(m, dtype=np.intc) for _ in range(4))
        self.oarg = np.zeros((m, 2), dtype=np.int64)
        self.num = np.zeros((m, 8), dtype=np.float64)  # ACN_KIN_NUM
        self.side = np.zeros((m, 4, n_axes), dtype=np.float64)
        self.stat = np.zeros((m, 3), dtype=np.float64)
        self.aid = np.zeros(m, dtype=np.int64)
        self.fix = np.zeros(m, dtype=np.uint8)


class _Found:
    """The forward passes' verdicts, one per candidate: each reason as a word, the verdict itself (:class:`_Verdict`)
    made when first read (most never are: a 1e7-sample drive's 60 000 a pass cost 0.2 s and 100 B each). A pass
    rewrites the kernel's rows from its resume on (:meth:`renew`), and the verdicts made of those rows go with them."""

    __slots__ = ("_d", "_ps", "reasons", "_made")

    def __init__(self, d: _Decider, ps: _Pass):
        self._d, self._ps = d, ps
        self.reasons: list[str] = []
        self._made: dict[int, _Verdict] = {}

    def renew(self, start: int, reasons: list[str]) -> None:
        """The rows from ``start`` on rewritten by a pass, with these reasons."""
        del self.reasons[start:]
        self.reasons.extend(reasons)
        for i in [i for i in self._made if i >= start]:
            del self._made[i]

    def __len__(self) -> int:
        return len(self.reasons)

    def __getitem__(self, i: int) -> _Verdict:
        v = self._made.get(i)
        if v is None:
            if not 0 <= i < len(self.reasons):
                raise IndexError(f"verdict {i}: {len(self.reasons)} candidates")
            v = self._made[i] = _Verdict(self, i)
        return v

    def __iter__(self):
        return (self[i] for i in range(len(self.reasons)))


class _Verdict:
    """One candidate's verdict of a forward pass: its reason; its side and its evidence in words made when read
    (most are never read but for the last pass's, and the words only once, at the end)."""

    __slots__ = ("_f", "_i", "_before")

    def __init__(self, found: _Found, i: int):
        self._f, self._i = found, i
        self._before: Side | None = None

    @property
    def reason(self) -> str:
        return self._f.reasons[self._i]

    @property
    def _d(self) -> _Decider:
        return self._f._d

    @property
    def _ps(self) -> _Pass:
        return self._f._ps

    @property
    def after(self) -> Side | None:
        """Its side after it, from the last backward pass (None before the first)."""
        after = self._d._after
        return None if after is None else after[self._i]

    @property
    def before(self) -> Side:
        if self._before is None:
            self._before = self._d._side(self._ps, self._i)
        return self._before

    @property
    def evidence(self) -> str:
        return self._d._words(self._ps, self._i, self.before)


class _Sides:
    """The sides of one backward pass (acn_kin_backward), candidate by candidate, each made when first read."""

    __slots__ = ("_d", "_rows", "_made")

    def __init__(self, d: _Decider, sides: np.ndarray, stat: np.ndarray, aid: np.ndarray, fix: np.ndarray):
        self._d, self._rows = d, (sides, stat, aid, fix)
        self._made: dict[int, Side] = {}

    def __len__(self) -> int:
        return len(self._rows[1])

    def __getitem__(self, i: int) -> Side:
        s = self._made.get(i)
        if s is None:
            sides, stat, aid, fix = self._rows
            s = self._made[i] = self._d._after_side(sides[i], stat[i], int(aid[i]), int(fix[i]))
        return s


@dataclass
class _Forward:
    """The forward filter's inputs and carried outputs as the kernel reads them (_Decider._kernel)."""

    ffi: object
    lib: object
    f: object  # acn_kin_fwd *
    out: object  # acn_kin_fwd_out *
    keep: list  # the buffers the two point into
    veto: np.ndarray  # (m,) uint8, the kernel's view of the vetoes
    acc: np.ndarray  # (m,) uint8, the accepted set
    mark_ok: np.ndarray  # the marks left
    ps: _Pass  # the verdicts' rows


class _Decider:
    def __init__(self, x, R, Ts, cands, fixes, p, t, start_sd: float = 0.0):
        self.start_sd = start_sd  # the model's prior sd of the start speed: a still start only when it is small
        cands = _Cands.of(cands, x.shape[1])
        self.x, self.R, self.Ts, self.cands, self.p, self.t = x, R, Ts, cands, p, t
        self.n = len(x)
        self.fixes = fixes
        self.q = p.level_walk**2
        self.fwd_events = _Events(cands, fixes, self.n, False)
        self.bwd_events = _Events(cands, fixes, self.n, True)
        self.veto: dict[int, str] = {}  # withdrawn: why
        self._sources: dict[tuple[str, int], str] = {}  # the words naming each aid (_source)
        self._bwd = None  # the backward events as the kernel reads them (backward)
        self._fwd: _Forward | None = None  # the forward filter's inputs as the kernel reads them (_kernel)
        self._after: _Sides | None = None  # the last backward pass's sides (_attach)
        # the forward filter's marks, {candidate: its slot in the kernel's marks} (the filter and its state before the
        # candidate's test, made at each test with no hypothesis open), its last pass's verdicts and the vetoes that
        # pass saw (forward)
        self._marks: dict[int, int] = {}
        self._mark_every = max(MARK_EVERY, -(-len(cands) // MARKS))
        self._found: _Found | list = []
        self._seen_veto: dict[int, str] = {}
        self._start: dict[bool, _Kinematic] = {}  # per direction (reversed?), the filter before any event
        self._stands: list[int] | None = None  # the candidates that may be stands (_short_before_stands)

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

    def forward(self) -> tuple[_Found, set[int]]:
        """The forward filter, deciding online; returns every candidate's verdict and the accepted set: the kernel's
        whole run over the events (acn_kin_forward), its verdicts' words made here when read (:meth:`_words`).

        Where nothing can tell (no fix, no rest yet), a candidate may be taken as a *hypothesis*: it is kept
        when the next ``CONFIRM`` candidates, tested with it, are consistent and the body moved between
        (a walk's stances: each closes the velocity of the stride before it); when one of them is found
        moving, or cannot be told, the filter goes back to before the hypothesis and goes on without it."""
        resume = self._resume()
        k = self._kernel()
        k.veto[:] = 0  # the vetoes the kernel reads
        k.veto[list(self.veto)] = 1
        ps = k.ps
        if k.lib.acn_kin_forward(k.f, -1 if resume is None else resume, k.out) != 0:
            raise ValueError(
                "rest decision: the forward filter's candidates or events are out of order or outside the record"
            )
        start = 0 if resume is None else resume
        reasons = [_REASONS[r] for r in ps.reason[start : len(self.cands)].tolist()]
        if not isinstance(self._found, _Found):
            self._found = _Found(self, ps)
        found = self._found
        found.renew(start, reasons)
        every = self._mark_every
        self._marks = {s * every: s for s in np.flatnonzero(k.mark_ok).tolist()}
        return found, set(np.flatnonzero(k.acc).tolist())

    def _resume(self) -> int | None:
        """The candidate whose mark the forward filter starts at (None: the record's start). A pass after the first
        decides as the last did up to the first candidate whose veto is new: it resumes at the last mark before it,
        the verdicts before the mark kept."""
        first = min((i for i, why in self.veto.items() if self._seen_veto.get(i) != why), default=len(self.cands))
        resume = max((i for i in self._marks if i <= first), default=None)
        self._seen_veto = dict(self.veto)
        self._marks = {} if resume is None else {i: s for i, s in self._marks.items() if i <= resume}
        return resume

    def _kernel(self) -> _Forward:
        """The forward filter's inputs as the kernel reads them, and its carried outputs: made once per decision."""
        if self._fwd is not None:
            return self._fwd
        from accelnav.estimate.fastsmooth import _lib

        mod = _lib()
        ffi, lib = mod.ffi, mod.lib
        p, cands, n_axes = self.p, self.cands, self.x.shape[1]
        kin = self._fresh(False)
        m = len(cands)
        ev = self.fwd_events
        arrays = {
            "ev_k": ev.k,
            "ev_kind": ev.kind,
            "ev_i": ev.i,
            "ev_z": ev.z,
            "ev_var": ev.var,
            "start": cands.start,
            "stop": cands.stop,
            "level": cands.level,
            "still": cands.still,
            "veto": np.zeros(m, dtype=np.uint8),
            "diffuse": np.array(DIFFUSE, dtype=np.float64),
        }
        types = {np.dtype(np.int64): "long[]", np.dtype(np.intc): "int[]", np.dtype(np.float64): "double[]",
                 np.dtype(np.uint8): "unsigned char[]"}  # fmt: skip
        f = ffi.new("acn_kin_fwd *")
        keep = [kin]
        for name, a in arrays.items():
            c = ffi.from_buffer(types[a.dtype], a)
            keep.append(c)
            setattr(f, name, c)
        for name, a in (("R", kin.R), ("qv", kin.qv)):
            c = ffi.from_buffer("double[]", a)
            keep.append(c)
            setattr(f, name, c)
        f.rec = kin.rec
        f.n_axes, f.n, f.Ts, f.q, f.n_ev, f.m = n_axes, self.n, self.Ts, self.q, len(ev), m
        for name in ("drift", "scale", "sigma", "gate", "tell", "level_still", "level_max", "still_k", "start_s",
                     "start_within_s", "rel"):  # fmt: skip
            setattr(f, name, float(getattr(p, name)))
        f.leak, f.start_sd, f.like, f.unlike, f.unlike_tell = LEAK, self.start_sd, LIKE, UNLIKE, UNLIKE_TELL
        f.motion, f.stride = MOTION, STRIDE
        f.confirm, f.within, f.peak_points = CONFIRM, WITHIN, PEAK_POINTS
        f.mark_every, f.n_marks = self._mark_every, m // self._mark_every + 1
        # carried from pass to pass: the accepted set, the proven stillness, the marks; scratch
        carried = {
            "acc": np.zeros(m, dtype=np.uint8),
            "proven": np.zeros(m, dtype=np.uint8),
            "mark_l": np.zeros((f.n_marks, 9), dtype=np.int64),
            "mark_d": np.zeros((f.n_marks, 13 * n_axes), dtype=np.float64),
            "mark_ok": np.zeros(f.n_marks, dtype=np.uint8),
            "work": np.zeros(2 * max(m, 1), dtype=np.float64),
            "tried": np.zeros(max(m, 1), dtype=np.uint8),
        }
        o = ffi.new("acn_kin_fwd_out *")
        for name, a in carried.items():
            c = ffi.from_buffer(types[a.dtype], a)
            keep.append(c)
            setattr(o, name, c)
        # the verdicts' rows, one set for every pass: a pass writes the rows from its resume on, the rows before it
        # are the verdicts it keeps (and the verdicts of an earlier pass after its resume are no longer read)
        ps = _Pass(m, n_axes)
        for name, t in _Pass.FIELDS:
            c = ffi.from_buffer(f"{t}[]", getattr(ps, name))
            keep.append(c)
            setattr(o, name, c)
        self._fwd = _Forward(ffi, lib, f, o, keep, arrays["veto"], carried["acc"], carried["mark_ok"], ps)
        return self._fwd

    def _side(self, ps: _Pass, i: int) -> Side:
        """Candidate i's forward side as the kernel wrote it in pass ``ps``."""
        s, (chi2, v, sd), aid = ps.side[i], ps.stat[i].tolist(), int(ps.aid[i])
        if aid < 0:
            source = "no aid"
        else:
            ev = self.fwd_events
            source = self._source("fix", ev.at(aid)) if ev.kind[aid] == 1 else self._source("rest", int(ev.i[aid]))
        return _made(s[0], s[1], chi2, source, bool(ps.fix[i]), s[2], s[3], (v, sd))

    def _words(self, ps: _Pass, i: int, s: Side) -> str:
        """Candidate i's evidence in words, from the kind and figures the kernel gave its verdict in pass ``ps``
        and its side ``s`` (what rests.py said of each verdict before the forward filter moved to C)."""
        p, c, Ts = self.p, self.cands[i], self.Ts
        base, flags = int(ps.base[i]), int(ps.flags[i])
        jump, allowed, moved, sd, bound, peak, end, tell = ps.num[i].tolist()
        dur = (c.stop - c.start) * Ts
        cannot = f"cannot tell: sd of v {sd:.2g} m/s before it ({'fixes too far' if s.fix else 'no fix'})"
        if base == _EV["gate off"]:
            ev = "every candidate accepted (gate 0)"
        elif base == _EV["veto"]:
            ev = self.veto[i]
        elif base == _EV["level"]:
            ev = f"level {jump:.2g} m/s^2 off the last rest's, more than {allowed:g} with " + (
                ("motion between" if flags & 1 else f"motion between, at {c.still:.2g} R: less still than the rests")
                if moved >= MOTION
                else f"no motion between (peak {moved:.2g} m/s)"
            )
        elif base == _EV["moving"]:
            what = "fixes imply" if s.fix and s.source.startswith("the fix") else "v"
            ev = f"{what} {_speed(s)} before it (from {s.source})"
        elif base == _EV["consistent"]:
            ev = f"v {_speed(s)} before it (from {s.source})"
        elif base == _EV["start sd"]:
            ev = cannot + f", no rest before (the model lets the run start at {self.start_sd:.3g} m/s)"
        elif base == _EV["still start"]:
            ev = (
                f"still start: {dur:.2f} s at {c.still:.2g} R from {c.start * Ts:.2f} s "
                "(assumed: the run starts at rest)"
            )
        elif base == _EV["no rest"]:
            ev = cannot + ", no rest before"
        elif base == _EV["not stand"]:
            ev = cannot + f"; {dur:.2f} s at {c.still:.2g} R is not a stand (still <= {bound:.2g} R)"
        elif base == _EV["still stand"]:
            ev = (
                f"still stand: {dur:.2f} s at {c.still:.2g} R; speed since the last stand {end:.2g} m/s after a "
                f"peak of {peak:.3g} m/s ({cannot})"
            )
        else:
            ev = (
                f"quiet at {c.still:.2g} R but no deceleration: speed since the last stand {end:.3g} m/s, "
                f"peak {peak:.3g} m/s (a stop needs <= {p.rel:g} of a peak >= 2 sd; {cannot})"
            )
        if flags & 4:  # a side within tell, refused by the bound for a short piece far less still than the rests
            ev += (
                f"; at {c.still:.2g} R, far less still than the proven rests and shorter than a stand: told only "
                f"within {tell:g} m/s"
            )
        if flags & 2:  # a hypothesis for a level that moved
            ev += f"; its level moved {jump:.2g} m/s^2"
        outcome, (by, why) = int(ps.outcome[i]), ps.oarg[i].tolist()
        if outcome == 1:
            ev += f"; not borne out: the candidate at {self.t[self.cands[by].start]:.2f} s {_REASONS[why]} with it"
        elif outcome == 2:
            ev += f"; not borne out by the next {WITHIN} candidates"
        elif outcome == 3:
            ev += "; not borne out: too few candidates after it"
        elif outcome == 4:
            ev = (
                f"{ev}; borne out by the next {CONFIRM} (the body moved between)"
                if _REASONS[why] == "consistent"
                else f"closes the velocity of the next {CONFIRM} (the body moved between; {ev.split(';')[0]})"
            )
        return ev

    def backward(self, acc: set[int]) -> _Sides:
        """The backward filter with the accepted set ``acc``: every candidate's side after it. It decides nothing
        (the sides are read after it): its whole run over the events is the kernel's (acn_kin_backward), the words
        naming each side's aid made here."""
        p, cands, n = self.p, self.cands, self.n
        kin = self._fresh(True)
        ffi, m, n_axes = kin.ffi, len(cands), kin.n_axes
        if self._bwd is None:  # the events as arrays, and each candidate's level and length: once per decision
            ev = self.bwd_events
            self._bwd = (
                ev.k,
                ev.kind,
                ev.i,
                ev.z,
                ev.var,
                cands.level,
                cands.stop - cands.start,
            )
        ev_k, ev_kind, ev_i, ev_z, ev_var, level, length = self._bwd
        accm = np.zeros(m, dtype=np.uint8)
        accm[sorted(acc)] = 1
        sides = np.full((m, 4, n_axes), np.nan)
        stat = np.full((m, 3), np.nan)
        aid = np.full(m, -1, dtype=np.int64)
        fix = np.zeros(m, dtype=np.uint8)
        buf = ffi.from_buffer
        rc = kin.lib.acn_kin_backward(
            n_axes, kin.s, kin.rec, kin.Ts, kin.q, kin._qv, kin._R, m, len(ev_k), buf("long[]", ev_k),
            buf("int[]", ev_kind), buf("long[]", ev_i), buf("double[]", ev_z), buf("double[]", ev_var),
            buf("unsigned char[]", accm), buf("double[]", level), buf("long[]", length), LEAK, p.drift, p.scale,
            p.sigma, buf("double[]", sides), buf("double[]", stat), buf("long[]", aid), buf("unsigned char[]", fix),
        )  # fmt: skip
        if rc != 0:
            raise ValueError("rest decision: the backward pass was refused by the kernel (its record or events)")
        assert n == len(self.x)
        return _Sides(self, sides, stat, aid, fix)

    def _attach(self, found: list, after: _Sides) -> None:
        """Each verdict's side after it: the last backward pass's (:attr:`_Verdict.after` reads it when looked at)."""
        self._after = after

    def _after_side(self, sides: np.ndarray, stat: np.ndarray, aid: int, fix: int) -> Side:
        """A backward side (one row of acn_kin_backward's outputs) as a Side, its aid named."""
        if aid < 0:
            source = "no aid"
        else:
            ev = self.bwd_events
            source = self._source("fix", ev.at(aid)) if ev.kind[aid] == 1 else self._source("rest", int(ev.i[aid]))
        chi2, v, sd = stat.tolist()
        return _made(sides[0], sides[1], chi2, source, bool(fix), sides[2], sides[3], (v, sd))

    def run(self) -> tuple[list, set[int]]:
        p = self.p
        for pass_no in range(p.passes + 1):
            found, acc = self.forward()
            after = self.backward(acc)
            self._attach(found, after)
            if p.gate == 0:
                return found, acc
            # each accepted rest against the other side, and against the positions both sides give it
            score = self._scores(found, acc, after)
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
                self._attach(found, after)
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

    def _scores(self, found: list, acc: set[int], after) -> dict[int, float]:
        """Each accepted rest's score: the larger of its side after it and the distance of the positions both sides
        give it (:meth:`_gap`, 0 unless both sides know the position through fixes). From the kernels' rows where
        they hold it (the sides made only for a rest with a fix on both sides), else from the sides."""
        if not isinstance(after, _Sides) or found is not self._found:
            return {i: max(after[i].chi2, self._gap(found[i].before, after[i], self.cands[i])) for i in acc}
        chi2, fixed = after._rows[1][:, 0].tolist(), after._rows[3]
        fix_before = found._ps.fix
        out = {}
        for i in acc:
            if fix_before[i] and fixed[i]:
                out[i] = max(after[i].chi2, self._gap(found[i].before, after[i], self.cands[i]))
            else:
                out[i] = max(chi2[i], 0.0)  # _gap's 0
        return out

    def _touch(self, i: int, j: int) -> bool:
        """Candidates i < j are pieces of one stretch: less than a window (``bridge_s``) between them."""
        return (self.cands[j].start - self.cands[i].stop) * self.Ts <= max(self.p.bridge_s, 2 * self.Ts)

    def _short_before_stands(self, found: list, acc: set[int]) -> dict[int, int]:
        """{j: i}: accepted rests j shorter than a stand (``start_s``) that were all that made the stand i after
        them "moving" (a stand: ``start_s`` long, still at the sensor's noise)."""
        p, out = self.p, {}
        order = sorted(acc)
        stops = self.cands.stop[order].tolist()
        monotone = all(a <= b for a, b in zip(stops, stops[1:], strict=False))  # the detector's spans: in order
        if self._stands is None:  # the candidates long and still enough for a stand: the same every pass
            c = self.cands
            short = (c.stop - c.start) * self.Ts < p.start_s
            self._stands = np.flatnonzero(~(short | (c.still > p.still_k))).tolist()
        todo = self._moving_after_rest(found)
        if monotone and found is self._found and todo and order:  # the kernels' verdicts: bisected at once
            start, stop = self.cands.start, self.cands.stop
            at = np.searchsorted(np.asarray(stops, dtype=np.int64), start[todo], side="right")  # bisect_right's
            j = np.asarray(order, dtype=np.int64)[np.maximum(at - 1, 0)]
            short = (at > 0) & ((stop[j] - start[j]) * self.Ts < p.start_s)
            for i, jj in zip(np.asarray(todo)[short].tolist(), j[short].tolist(), strict=True):
                if i not in self.veto:
                    out.setdefault(jj, i)
            return out
        for i in todo:
            if i in self.veto:
                continue
            j = self._last_before(order, stops if monotone else None, self.cands[i].start)
            if j is not None and (self.cands[j].stop - self.cands[j].start) * self.Ts < p.start_s:
                out.setdefault(j, i)
        return out

    def _moving_after_rest(self, found: list) -> list[int]:
        """The stands (:meth:`_short_before_stands`) found moving by the forward side from a rest before them, in
        order. From the forward pass' rows where the verdicts are its (a stand's reason code, its side's aid and that
        event's kind; 24 000 sides a 1e7-sample drive no longer makes for their source's first words), else from the
        verdicts' sides."""
        if found and found is self._found:
            ps, stands = found._ps, np.asarray(self._stands, dtype=np.int64)
            aid = ps.aid[stands]
            keep = (ps.reason[stands] == _REASONS.index("moving")) & (aid >= 0)
            keep[keep] = self.fwd_events.kind[aid[keep]] != 1  # a rest's end, not a fix: "the rest at ..."
            return stands[keep].tolist()
        return [i for i in self._stands if found[i].reason == "moving" and found[i].before is not None
                and found[i].before.source.startswith("the rest")]  # fmt: skip

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


def _candidates(x, ok, R, spans) -> _Cands:
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
    if np.any(starts[1:] <= starts[:-1]):  # the forward filter's kernel tests them in this order
        raise ValueError("spans: in time order, each starting after the one before")
    mod = _lib()
    ffi = mod.ffi
    x = np.ascontiguousarray(x, dtype=np.float64)
    usable = np.array(ok[:, 0], dtype=np.uint8)  # ok.all(axis=1), column by column: numpy's strided all is slower
    for j in range(1, n_axes):
        usable &= ok[:, j]
    R = np.ascontiguousarray(R, dtype=np.float64)
    level = np.zeros((len(starts), n_axes))
    still = np.zeros(len(starts))
    if len(starts):
        mod.lib.acn_kin_cands(
            n_axes, ffi.from_buffer("double[]", x), ffi.from_buffer("unsigned char[]", usable), len(starts),
            ffi.from_buffer("long[]", starts), ffi.from_buffer("long[]", stops), ffi.from_buffer("double[]", R),
            ffi.from_buffer("double[]", level), ffi.from_buffer("double[]", still),
        )  # fmt: skip
    return _Cands(starts, stops, level, still)


class _Cands(Sequence):
    """The candidates as arrays, what the kernels read: first samples, ends, levels (m, n_axes) and stillness; each
    :class:`Candidate` made when read (``cands[i]``: the same numbers, its level a row of ``level``). A drive of 1e7
    samples has 60 000 candidates: as objects they held 260 B each (its level an array of its own), and their levels
    gathered again for the kernels cost 0.1 s a time."""

    __slots__ = ("start", "stop", "level", "still")

    def __init__(self, start: np.ndarray, stop: np.ndarray, level: np.ndarray, still: np.ndarray):
        self.start, self.stop, self.level, self.still = start, stop, level, still

    @classmethod
    def of(cls, cands, n_axes: int) -> _Cands:
        """``cands`` (a list of :class:`Candidate`, or _Cands) as _Cands."""
        if isinstance(cands, _Cands):
            return cands
        m = len(cands)
        return cls(
            np.fromiter((c.start for c in cands), dtype=np.int64, count=m),
            np.fromiter((c.stop for c in cands), dtype=np.int64, count=m),
            np.array([c.level for c in cands], dtype=np.float64).reshape(m, n_axes),
            np.fromiter((c.still for c in cands), dtype=np.float64, count=m),
        )

    def __len__(self) -> int:
        return len(self.start)

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        m = len(self.start)
        if not -m <= i < m:
            raise IndexError(f"candidate {i}: {m} candidates")
        i = i + m if i < 0 else i
        return Candidate(int(self.start[i]), int(self.stop[i]), self.level[i], float(self.still[i]))

    def __iter__(self):
        spans = zip(self.start.tolist(), self.stop.tolist(), self.level, self.still.tolist(), strict=True)
        return (Candidate(a, b, lv, s) for a, b, lv, s in spans)


def decide(x, ok, R, Ts: float, t: np.ndarray | Clock, spans, fixes, p, start_sd: float = 0.0) -> list[RestDecision]:
    """The decision on every candidate span [a, b) of ``spans`` (see the module docstring). ``x`` (N, n_axes):
    acceleration less the model's bias mean (0 where not ``ok``); ``t``: the times (N,), or a :class:`Clock`;
    ``fixes``: per axis column a list of position-fix measurements (accelnav.estimate.kf) or None."""
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
    dec = _Decider(x, R, Ts, _candidates(x, ok, R, spans), fixes, p, t, start_sd)
    cands = dec.cands
    try:
        found, acc = dec.run()
        after = dec._after
    finally:
        # the verdicts and the sides refer back to the decider (they make their words and sides from it when read):
        # without them it goes with its last reference, and its record's sums (1.4 GB on a 1e7-sample drive) with
        # it, not at the next collection of cycles, while the smoother runs
        dec._found, dec._after = [], None
    # they refer to a copy of it that holds what the words read (the aids' names, the vetoes, the parameters), not
    # the record, its sums or its times
    words = object.__new__(_Decider)
    keep = ("p", "cands", "Ts", "veto", "start_sd", "fwd_events", "bwd_events", "_sources")
    words.__dict__.update({k: dec.__dict__[k] for k in keep}, _after=None)
    # the times the words name: the clock itself (two numbers), else the candidates' first and last samples', the fixes'
    words.t = t if isinstance(t, Clock) else _TimesAt(t, dec.fwd_events.k)
    for ev in (dec.fwd_events, dec.bwd_events):  # the words name aids by kind and index: the fixes' figures go
        ev.z = ev.var = None
    if isinstance(found, _Found):
        found._d = words
    if isinstance(after, _Sides):
        after._d = words
    return _verdicts(cands, found, acc, after)


def _verdicts(cands: _Cands, found: _Found, acc: set[int], after: _Sides | None) -> list[RestDecision]:
    """Each candidate's record: its verdict, the statistics, the evidence in words made when read (:class:`_Decided`).
    The statistics are the kernels' rows as they wrote them (the sides' (chi2, |v|, sd): the forward pass's rows, one
    set that each pass rewrote from its resume on, and the last backward pass's), read without making the sides."""
    if not isinstance(found, _Found) or not isinstance(after, _Sides | None):
        return _verdicts_of_sides(cands, found, acc)
    rows, out, made = _Rows(cands, found, acc, after), [], object.__new__
    for i in range(len(found)):
        d = made(_Decided)  # the frozen dataclass' fields read from the rows, nothing set but where they are
        object.__setattr__(d, "_rows", rows)
        object.__setattr__(d, "_i", i)
        out.append(d)
    return out


def _verdicts_of_sides(cands: list[Candidate], found: list, acc: set[int]) -> list[RestDecision]:
    """:func:`_verdicts` of verdicts that hold their sides (``before``, ``after``: a filter in Python, the reference
    of tests/support/rests_reference.py), the words made at once."""
    out = []
    for i, (c, f) in enumerate(zip(cands, found, strict=True)):
        b, a = f.before, f.after
        vb, sb = _norms(b)
        va, sa = _norms(a)
        chi2 = max(s.chi2 for s in (b, a) if s is not None) if (b or a) else math.nan
        lv = c.level
        d = object.__new__(RestDecision)
        d.__dict__.update(
            start=c.start, stop=c.stop, accepted=i in acc, reason=f.reason, evidence=_evidence(f, a), still=c.still,
            level=math.sqrt(lv.dot(lv)), v_before=vb, sd_before=sb, v_after=va, sd_after=sa, chi2=chi2,
        )  # fmt: skip
        out.append(d)
    return out
