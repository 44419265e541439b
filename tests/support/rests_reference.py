"""The parts of the rest decision (accelnav.estimate.rests) as they were before its rewrites for speed (issue 31,
its cost): the kinematic filter in numpy on (n_axes, 3, 3) arrays per event, the functions that read it as
arrays (a side's test, the level's jump), each candidate's statistics in numpy span by span, the backward
filter event by event in Python, np.median and np.linalg.norm, every candidate's peak speed computed at once, a
new filter per pass, each pass's forward filter from the start, the rests before a stand listed whole, the
chi-square's tail by scipy. Kept as the reference the rewrites must decide exactly like:
tests/estimate/test_rest_decision_same.py swaps them in (:func:`swapped`), and bench/speed/bench_rest_decision.py
times both."""

from __future__ import annotations

import contextlib
import math
import operator
from dataclasses import dataclass

import numpy as np

from accelnav.estimate import rests
from accelnav.estimate.rests import (
    ACCEPT_REASONS,
    CONFIRM,
    DIFFUSE,
    LEAK,
    LIKE,
    MOTION,
    PEAK_POINTS,
    REFUSE_REASONS,
    STRIDE,
    UNLIKE,
    UNLIKE_TELL,
    WITHIN,
    Candidate,
    Side,
)


def chi2_equivalent(x: float, dof: int) -> float:
    """The one-degree chi-square value with the upper tail of ``x`` under dof degrees of freedom, by scipy's
    gammaincc and erfcinv, as it was before the kernel's closed form."""
    if dof == 1 or not math.isfinite(x):
        return x
    from scipy.special import erfcinv, gammaincc

    tail = float(gammaincc(dof / 2.0, x / 2.0))
    if tail <= 0.0:
        return math.inf
    return float(2.0 * erfcinv(tail) ** 2)


def _update(X: np.ndarray, P: np.ndarray, i: int, z: np.ndarray, r: np.ndarray, rows=slice(None)) -> None:
    """In place, for the axes ``rows``: the scalar measurement z = s_i + v, v ~ N(0, r)."""
    Pi = P[rows, :, i]  # (m, 3)
    S = Pi[:, i] + r
    K = Pi / S[:, None]
    X[rows] += K * (z - X[rows, i])[:, None]
    P[rows] -= K[:, :, None] * Pi[:, None, :]
    P[rows] = 0.5 * (P[rows] + np.swapaxes(P[rows], 1, 2))


class ReferenceKinematic:
    """The kinematic filter of the module docstring over one direction of time of one record."""

    def __init__(self, x: np.ndarray, Ts: float, R: np.ndarray, q: float):
        n, self.n_axes = x.shape
        self.Ts, self.q, self.qv = Ts, q, R * Ts
        self.V = np.zeros((n + 1, self.n_axes))
        np.cumsum(x * Ts, axis=0, out=self.V[1:])  # V[k] = Ts sum_{i<k} x[i]
        self.A = np.zeros((n + 1, self.n_axes))
        np.cumsum(np.abs(x) * Ts, axis=0, out=self.A[1:])  # A[k] = Ts sum_{i<k} |x[i]|: how much moved
        self.W = np.zeros((n + 1, self.n_axes))
        np.cumsum(self.V[:-1] * Ts, axis=0, out=self.W[1:])  # W[k] = Ts sum_{i<k} V[i]
        self.X = np.zeros((self.n_axes, 3))
        self.P = np.zeros((self.n_axes, 3, 3))
        self.P[:, [0, 1, 2], [0, 1, 2]] = DIFFUSE
        self.k = 0
        self.aid_k = 0  # sample of the last aid

    def copy(self) -> ReferenceKinematic:
        new = object.__new__(ReferenceKinematic)
        new.__dict__.update(self.__dict__)
        new.X, new.P = self.X.copy(), self.P.copy()
        return new

    def to(self, k: int) -> None:
        """Propagate the state from sample self.k to sample k."""
        m = k - self.k
        if m <= 0:
            return
        Ts, q = self.Ts, self.q
        D = m * Ts
        c = Ts * Ts * m * (m - 1) / 2.0
        k0 = self.k
        dV = self.V[k] - self.V[k0]
        dW = self.W[k] - self.W[k0] - D * self.V[k0]
        X = self.X
        r, u, e = X[:, 0].copy(), X[:, 1].copy(), X[:, 2].copy()
        X[:, 0] = r + D * u + dW - c * e
        X[:, 1] = u + dV - D * e
        F = np.array([[1.0, D, -c], [0.0, 1.0, -D], [0.0, 0.0, 1.0]])
        # the level's random walk, integrated once into u and twice into r (signs: u and r get -e), and the
        # velocity noise of the integrated sensor noise
        qd = np.array(
            [
                [q * D**5 / 20, q * D**4 / 8, -q * D**3 / 6],
                [q * D**4 / 8, q * D**3 / 3, -q * D**2 / 2],
                [-q * D**3 / 6, -q * D**2 / 2, q * D],
            ]
        )
        qv = self.qv[:, None, None] * np.array([[D**3 / 3, D**2 / 2, 0.0], [D**2 / 2, D, 0.0], [0.0, 0.0, 0.0]])
        P = F @ self.P @ F.T + qd + qv
        self.P = P
        self.k = k

    def rest(self, k: int, sigma: float) -> None:
        self.to(k)
        _update(self.X, self.P, 1, np.zeros(self.n_axes), np.full(self.n_axes, sigma * sigma))
        self.aid_k = k

    def fix(self, k: int, j: int, z: float, var: float) -> None:
        self.to(k)
        _update(self.X, self.P, 0, np.array([z]), np.array([var]), rows=slice(j, j + 1))
        self.aid_k = k

    def velocity_given_level(self, level: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, ...]:
        """(u, sd of u, e, r, sd of r) at the current sample, conditioned on e = level (variance ``var``), state
        unchanged."""
        X, P = self.X.copy(), self.P.copy()
        _update(X, P, 2, level, var)
        sd = np.sqrt(np.maximum(np.diagonal(P, axis1=1, axis2=2), 0.0))
        return X[:, 1], sd[:, 1], X[:, 2], X[:, 0], sd[:, 0]


def reference_side(
    kin: ReferenceKinematic,
    c: Candidate,
    R: np.ndarray,
    sigma: float,
    drift: float,
    scale: float,
    source: str,
    fix: bool,
    sign: float,
) -> Side:
    e_prior, known = kin.X[:, 2].copy(), kin.P[:, 2, 2] < 1.0
    v, sd0, _, r, r_sd = kin.velocity_given_level(c.level, R / max(c.stop - c.start, 1))
    # the level's path between the last aid and here is taken as linear; a leak that changed by L since then
    # may have changed along any path: up to L D / 2 of velocity, L D / 4 allowed (one sd)
    D = (kin.k - kin.aid_k) * kin.Ts
    # and a mean acceleration error no level explains (a leak changing within the move): drift D; and errors in
    # proportion to the acceleration itself (a scale factor, a level frame turned during a stride: on a real
    # foot a stride leaves 0.2-0.8 m/s in the integral): scale x integral of |x| since the last aid
    moved = kin.A[kin.k] - kin.A[kin.aid_k]
    widen = np.where(known, (LEAK * (c.level - e_prior) * D) ** 2, 0.0) + (drift * D) ** 2 + (scale * moved) ** 2
    sd = np.sqrt(sd0 * sd0 + widen)
    # the position the same way: the velocity's widening over the time since the aid
    r_sd = np.sqrt(r_sd * r_sd + widen * D * D)
    # over the axes: the sum, as the chi-square of one axis with the same tail (chi2_equivalent): a move along one
    # axis is not diluted by the others' rest, and three quiet axes do not add up to a move
    chi2 = chi2_equivalent(float(np.sum(v * v / (sd * sd + sigma * sigma))), len(v))
    return Side(sign * v, sd, chi2, source, fix, r, r_sd)


def reference_jump(self, kin: ReferenceKinematic, c: Candidate) -> float:
    """|level - the filter's level| over the axes, beyond 3 sd of the filter's level; 0 while it has none."""
    sd = np.sqrt(np.maximum(kin.P[:, 2, 2], 0.0))
    if np.any(sd >= 1.0):
        return 0.0
    return float(np.linalg.norm(np.maximum(np.abs(c.level - kin.X[:, 2]) - 3.0 * sd, 0.0)))


def reference_test(self, kin: ReferenceKinematic, k: int, i: int, st: dict) -> tuple[float, Side]:
    """The forward filter taken to candidate i's first sample k: the level's jump there and its side, as the old
    forward filter made them (its own lines, gathered here)."""
    p, c = self.p, self.cands[i]
    kin.to(k)
    jump = reference_jump(self, kin, c)
    return jump, reference_side(kin, c, self.R, p.sigma, p.drift, p.scale, st["source"], st["fix"], 1.0)


def reference_median(values: list[float]) -> float:
    return float(np.median(values))


def reference_tell_bound(self, c: Candidate, like: bool) -> float:
    """The sd a side must reach to call a candidate consistent: ``tell``, or UNLIKE_TELL x ``tell`` for one far less
    still than the record's proven rests and shorter than a stand (``start_s``). Such a piece is a moment of a body
    that moves (a trunk mid-stride) unless the velocity is known well: a lower back walking reads 20-120 R in its
    quietest tenth of a second against 1-2 R standing, and mobgap's MS_001 trial 1 (levelled by accelnav.level at its
    standings) accepted a 0.19 s piece at 94 R mid-walk on a side of 0.86 +/- 0.37 m/s, which then refused the
    standing after the walk as moving. A stand's length keeps ``tell``: a stop with a knock in it, or an idling
    engine, is unsteady but long."""
    short = (c.stop - c.start) * self.Ts < self.p.start_s
    return UNLIKE_TELL * self.p.tell if short and not like else self.p.tell


def reference_judge(self, i: int, c: Candidate, s: Side, st: dict, moved, jump: float) -> tuple[str, str]:
    """(reason, evidence) of candidate i from the forward side ``s`` and the other lines of evidence."""
    p = self.p
    # a level may move far after a move (a foot turns, a mount tilts) in a candidate as still as the record's
    # proven rests; one far less still (a push held, a braking) keeps the level of a body that did not turn
    like = not st["proven"] or c.still <= max(p.still_k, LIKE * reference_median(st["proven"]))
    if like:
        allowed = p.level_max if moved[0] >= MOTION else p.level_still
    else:  # the motion seen with the rest's own level (the candidate's, a push's, would hide it)
        allowed = UNLIKE * p.level_still if moved[2] >= MOTION else p.level_still
    if p.gate == 0:
        return "gate off", "every candidate accepted (gate 0)"
    if i in self.veto:
        return "moving", self.veto[i]
    if jump > allowed:
        return "level jumped", f"level {jump:.2g} m/s^2 off the last rest's, more than {allowed:g} with " + (
            ("motion between" if like else f"motion between, at {c.still:.2g} R: less still than the rests")
            if moved[0] >= MOTION
            else f"no motion between (peak {moved[0]:.2g} m/s)"
        )
    if s.chi2 > p.gate:
        what = "fixes imply" if s.fix and st["source"].startswith("the fix") else "v"
        return "moving", f"{what} {reference_speed(s)} before it (from {s.source})"
    # a rule added after the rewrites (level-track: a short piece far less still than the proven rests is told only
    # on a side within UNLIKE_TELL x tell): new behaviour, not a part the rewrites changed, so the reference
    # decides by it too and the comparison stays one of the rewritten code paths
    bound = reference_tell_bound(self, c, like)
    if self._tells(s, bound):
        st["proven"].append(c.still)
        return "consistent", f"v {reference_speed(s)} before it (from {s.source})"
    stand = reference_peak(self, c, st["last_stand"]) if st["last_stand"] is not None else moved
    reason, evidence = reference_other_evidence(self, c, s, st["last_end"], st["proven"], st["fix"], stand)
    if bound < p.tell and self._tells(s):
        evidence += (
            f"; at {c.still:.2g} R, far less still than the proven rests and shorter than a stand: told only "
            f"within {bound:g} m/s"
        )
    if reason == "still start":
        st["proven"].append(c.still)
    return reason, evidence


def reference_peak(self, c: Candidate, last_end) -> tuple[float, float, float]:
    """(peak, end) speed integrated from the last rest's end to the candidate's start, the level linear
    from the rest's to the candidate's, and the peak with the rest's level kept; the peaks on at most
    PEAK_POINTS points of the way (a cost per candidate that does not grow with the time since the rest)."""
    Ts, V = self.Ts, self.V
    e, u0, e0 = last_end
    a = max(c.start, e)
    k = np.linspace(e, a, min(a - e + 1, PEAK_POINTS)).round().astype(np.int64)
    D = max(a - e, 1) * Ts
    tk = ((k - e) * Ts)[:, None]
    vk = V[k] - V[e] - e0[None, :] * tk - (c.level - e0)[None, :] * (tk * tk / (2 * D)) + u0[None, :]
    speed = np.sqrt(np.sum(vk * vk, axis=1))
    flat = vk + (c.level - e0)[None, :] * (tk * tk / (2 * D))  # the rest's own level all the way
    return float(speed.max()), float(speed[-1]), float(np.sqrt(np.max(np.sum(flat * flat, axis=1))))


def reference_speed(s: Side) -> str:
    return f"{float(np.linalg.norm(s.v)):.3g} +/- {float(np.sqrt(np.mean(s.sd**2))):.2g} m/s"


def reference_fresh(self, reverse: bool):
    """A new filter per pass, its sums over the record made again, as the old passes did."""
    return rests._Kinematic(self.x[::-1] if reverse else self.x, self.Ts, self.R, self.q)


def reference_norms(s: Side | None) -> tuple[float, float]:
    if s is None:
        return float("nan"), float("nan")
    return float(np.linalg.norm(s.v)), float(np.sqrt(np.mean(s.sd**2)))


def reference_last_before(self, order: list[int], stops, k: int):
    """The last accepted rest that ends by sample k, the rests before it listed whole, as it was."""
    before = [j for j in order if self.cands[j].stop <= k]
    return before[-1] if before else None


@dataclass
class Found:
    """One candidate's state during the passes, as the Python forward filter kept it."""

    reason: str = "cannot tell"
    evidence: str = ""
    before: Side | None = None
    after: Side | None = None


def reference_other_evidence(self, c: Candidate, s: Side, last_end, proven: list[float], fix_seen: bool, moved):
    """The lines of evidence besides the sides (a still start, a still stand), as the Python forward filter read
    them."""
    p, Ts = self.p, self.Ts
    sd = float(s.sd.max())
    dur = (c.stop - c.start) * Ts
    cannot = f"cannot tell: sd of v {sd:.2g} m/s before it ({'fixes too far' if fix_seen else 'no fix'})"
    if last_end is None:
        if self.start_sd > p.tell:
            return "cannot tell", cannot + f", no rest before (the model lets the run start at {self.start_sd:.3g} m/s)"
        if c.start * Ts <= p.start_within_s and dur >= p.start_s and c.still <= p.still_k:
            return "still start", (
                f"still start: {dur:.2f} s at {c.still:.2g} R from {c.start * Ts:.2f} s "
                "(assumed: the run starts at rest)"
            )
        return "cannot tell", cannot + ", no rest before"
    bound = max(p.still_k, 2.0 * reference_median(proven)) if proven else p.still_k
    if dur < p.start_s or c.still > bound:
        return "cannot tell", cannot + f"; {dur:.2f} s at {c.still:.2g} R is not a stand (still <= {bound:.2g} R)"
    peak, end = moved[:2]
    if end <= p.rel * peak and peak >= 2.0 * sd:
        return "still stand", (
            f"still stand: {dur:.2f} s at {c.still:.2g} R; speed since the last stand {end:.2g} m/s after a "
            f"peak of {peak:.3g} m/s ({cannot})"
        )
    return "no deceleration", (
        f"quiet at {c.still:.2g} R but no deceleration: speed since the last stand {end:.3g} m/s, "
        f"peak {peak:.3g} m/s (a stop needs <= {p.rel:g} of a peak >= 2 sd; {cannot})"
    )


def _source(self, kind: str, at: int) -> str:
    t = self.t
    if kind == "fix":
        return f"the fix at {t[at]:.2f} s"
    c = self.cands[at]
    return f"the rest at {t[c.start]:.2f}-{t[c.stop - 1]:.2f} s"


def reference_events(self, reverse: bool) -> list[tuple]:
    """(sample, order, kind, payload) of one direction, sorted: a candidate's test before anything at its first
    sample, its end at its last; as the events were before they were arrays (rests._Events)."""
    n, ev = self.n, []
    for i, c in enumerate(self.cands):
        a, e = (n - c.stop, n - 1 - c.start) if reverse else (c.start, c.stop - 1)
        ev.append((a, 0, "test", i))
        ev.append((e, 2, "end", i))
    for j, fx in enumerate(self.fixes):
        for m in fx:
            ev.append((n - 1 - m.k if reverse else m.k, 1, "fix", (j, m.z, m.R, m.k)))
    ev.sort(key=operator.itemgetter(0, 1))  # stable: fixes at one sample keep their order
    return ev


def reference_forward(self):
    """The forward filter, deciding online, event by event in Python, every pass from the record's start (no marks
    to resume at), as it was before it moved to C (acn_kin_forward)."""
    p, cands, Ts, t = self.p, self.cands, self.Ts, self.t
    self._seen_veto = dict(self.veto)
    kin = self._fresh(False)
    self.V = kin.V
    found = [Found() for _ in cands]
    st = {"acc": set(), "source": "no aid", "fix": False, "last_end": None, "last_stand": None, "proven": []}
    e = 0
    pending = None  # (hypothesis i, event index of its test, saved kinematics and state, confirmations, seen)
    tried: set[int] = set()  # hypotheses already refuted in this pass
    ev = reference_events(self, False)
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
            st["source"], st["fix"] = _source(self, "fix", k), True
            continue
        i = pay
        c = cands[i]
        acc = st["acc"]
        if kind == "end":
            if i in acc:
                kin.rest(k, p.sigma)
                X = kin.X
                st["last_end"] = (k, X[:, 1].copy(), X[:, 2].copy())
                if (c.stop - c.start) * Ts >= p.start_s:  # a stand: what a stop's kinematics start from
                    st["last_stand"] = st["last_end"]
                st["source"] = _source(self, "rest", i)
            continue
        jump, s = reference_test(self, kin, k, i, st)
        f = found[i]
        f.before, f.evidence = s, ""
        moved = reference_peak(self, c, st["last_end"]) if st["last_end"] is not None else (0.0, 0.0, 0.0)
        f.reason, f.evidence = reference_judge(self, i, c, s, st, moved, jump)
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
            pending = (i, e, (kin.copy(), {**st, "acc": set(acc), "proven": list(st["proven"])}), 0, 0)
            if f.reason == "consistent":
                f.evidence += f"; its level moved {jump:.2g} m/s^2"
            else:
                f.reason = "hypothesis"
        if f.reason in ACCEPT_REASONS or f.reason == "hypothesis":
            acc.add(i)
            kin.rest(k, p.sigma)
    return found, st["acc"]


def reference_candidates(x, ok, R, spans) -> list[Candidate]:
    """Each candidate's statistics in numpy, span by span, as decide() made them."""
    n_axes = x.shape[1]
    usable = ok.all(axis=1)
    cands = []
    for a, b in spans:
        use = usable[a:b]
        xs = x[a:b][use] if use.any() else np.zeros((1, n_axes))
        var = xs.var(axis=0) if len(xs) > 1 else R.copy()
        cands.append(Candidate(a, b, xs.mean(axis=0), float(np.mean(var / R))))
    return cands


def reference_backward(self, acc: set[int]) -> list[Side | None]:
    """The backward filter event by event in Python, as it was."""
    p, cands, t, n = self.p, self.cands, self.t, self.n
    kin = self._fresh(True)
    out: list[Side | None] = [None] * len(cands)
    source, fix_seen = "no aid", False
    for k, _, kind, pay in reference_events(self, True):
        if kind == "fix":
            j, z, var, k0 = pay
            kin.fix(k, j, z, var)
            source, fix_seen = f"the fix at {t[k0]:.2f} s", True
            continue
        i = pay
        c = cands[i]
        if kind == "end":
            if i in acc:
                kin.rest(k, p.sigma)
                source = f"the rest at {t[c.start]:.2f}-{t[c.stop - 1]:.2f} s"
            continue
        kin.to(k)
        out[i] = reference_side(kin, c, self.R, p.sigma, p.drift, p.scale, source, fix_seen, -1.0)
        if i in acc:
            kin.rest(k, p.sigma)
    assert n == len(self.x)
    return out


def reference_attach(self, found, after) -> None:
    """Each verdict's side after it, set on it, as the passes did."""
    for f, s in zip(found, after, strict=True):
        f.after = s


# where each old part goes in accelnav.estimate.rests: swapped in together, they make the module decide as it
# did before its rewrite
SWAPS = {
    (rests, "_Kinematic"): ReferenceKinematic,
    (rests, "_speed"): reference_speed,
    (rests, "_norms"): reference_norms,
    (rests, "_candidates"): reference_candidates,
    (rests, "chi2_equivalent"): chi2_equivalent,
    (rests._Decider, "_fresh"): reference_fresh,
    (rests._Decider, "backward"): reference_backward,
    (rests._Decider, "_attach"): reference_attach,
    (rests._Decider, "forward"): reference_forward,
    (rests._Decider, "_last_before"): reference_last_before,
}


@contextlib.contextmanager
def swapped():
    """accelnav.estimate.rests with its old parts in, the new ones put back after."""
    kept = {key: getattr(*key) for key in SWAPS}
    try:
        for (owner, name), old in SWAPS.items():
            setattr(owner, name, old)
        yield
    finally:
        for (owner, name), new in kept.items():
            setattr(owner, name, new)
