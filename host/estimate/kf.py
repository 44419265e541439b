"""Float64 reference: the 4-state Kalman filter of one axis and its RTS smoother.

This is the oracle the rest of accelnav is checked against, so it is written
for clarity: x, P, F, Q, H, R, K, S, y as in the textbook, the equation as a
comment above the line that computes it, one step at a time.

Conventions (one axis, N samples, k = 0 .. N-1):

* ``F`` maps x[k] to x[k+1]:  x[k+1] = F x[k] + b + w[k],  w ~ N(0, Q).
* The prior at sample 0 is (x0, P0) from the design; the prior at k >= 1 is
  the prediction from the posterior at k-1.
* At sample k the filter first predicts (k >= 1), then applies the
  acceleration measurement z[k] = H x[k] + v, v ~ N(0, R) unless the sample is
  marked invalid (missing or rail-clipped: predict only), then every extra
  measurement given for sample k (position fix, zero-velocity update), one
  scalar update after another, in the order given.
* ``x_prior[k], P_prior[k]`` are x[k|k-1], P[k|k-1]; ``x_post[k], P_post[k]``
  are x[k|k], P[k|k] after all the updates of sample k.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from accelnav.model.design import AxisDesign
from accelnav.progress import Progress


@dataclass(frozen=True)
class Measurement:
    """A scalar measurement z = h . x[k] + v, v ~ N(0, R), at sample k."""

    k: int
    h: tuple[float, float, float, float]
    z: float
    R: float


def position_fix(k: int, r: float, sigma: float) -> Measurement:
    """A position fix r [m] with standard deviation sigma [m] at sample k."""
    return Measurement(k, (1.0, 0.0, 0.0, 0.0), float(r), float(sigma) ** 2)


def zero_velocity(k: int, sigma: float = 1e-3) -> Measurement:
    """A zero-velocity update at sample k: u = 0 with standard deviation sigma [m/s]."""
    return Measurement(k, (0.0, 1.0, 0.0, 0.0), 0.0, float(sigma) ** 2)


@dataclass(frozen=True)
class Aids:
    """Scalar measurements as arrays, in their given order: a list of :class:`Measurement` without one
    Python object per measurement (a long walk has 1e5 and more zero-velocity updates, and building and
    unbuilding their objects cost more than the smoother)."""

    k: np.ndarray  # (n,) int64 sample
    h: np.ndarray  # (n, 4)
    z: np.ndarray  # (n,)
    R: np.ndarray  # (n,)

    @classmethod
    def of(cls, ms: Sequence[Measurement] | Aids) -> Aids:
        if isinstance(ms, Aids):
            return ms
        n = len(ms)
        return cls(
            np.array([m.k for m in ms], dtype=np.int64).reshape(n),
            np.array([m.h for m in ms], dtype=np.float64).reshape(n, 4),
            np.array([m.z for m in ms], dtype=np.float64).reshape(n),
            np.array([m.R for m in ms], dtype=np.float64).reshape(n),
        )

    @classmethod
    def zero_velocity(cls, ks: np.ndarray, sigma: np.ndarray | float) -> Aids:
        """:func:`zero_velocity` at every sample of ``ks``, with standard deviations ``sigma`` [m/s]."""
        ks = np.asarray(ks, dtype=np.int64).reshape(-1)
        h = np.zeros((len(ks), 4))
        h[:, 1] = 1.0
        R = np.broadcast_to(np.asarray(sigma, dtype=np.float64) ** 2, ks.shape).copy()
        return cls(ks, h, np.zeros(len(ks)), R)

    def concat(self, other: Aids) -> Aids:
        """These, then ``other``: the other itself when these are none (a run's rests without fixes are
        millions of updates, 56 B each per axis: not copied whole to add nothing), and the reverse."""
        if not len(self):
            return other
        if not len(other):
            return self
        return Aids(*(np.concatenate((a, b)) for a, b in zip(self._parts(), other._parts(), strict=True)))

    def take(self, idx: np.ndarray) -> Aids:
        return Aids(*(a[idx] for a in self._parts()))

    def measurements(self) -> list[Measurement]:
        return [
            Measurement(int(k), tuple(float(v) for v in h), float(z), float(r))
            for k, h, z, r in zip(self.k, self.h, self.z, self.R, strict=True)
        ]

    def _parts(self) -> tuple[np.ndarray, ...]:
        return self.k, self.h, self.z, self.R

    def __len__(self) -> int:
        return len(self.k)


@dataclass(frozen=True)
class FilterResult:
    """Priors and posteriors of every sample (see the module docstring)."""

    x_prior: np.ndarray  # (N, 4)
    P_prior: np.ndarray  # (N, 4, 4)
    x_post: np.ndarray  # (N, 4)
    P_post: np.ndarray  # (N, 4, 4)
    y: np.ndarray  # (N,) innovation of the acceleration measurement, NaN where skipped
    S: np.ndarray  # (N,) its variance, NaN where skipped

    def __len__(self) -> int:
        return len(self.x_post)


@dataclass(frozen=True)
class SmoothResult:
    """Smoothed x[k|N-1] and P[k|N-1] of every sample."""

    x: np.ndarray  # (N, 4)
    P: np.ndarray  # (N, 4, 4)


def _group_extras(extras: Iterable[Measurement], n: int) -> dict[int, list[Measurement]]:
    by_k: dict[int, list[Measurement]] = {}
    for m in extras:
        if not 0 <= m.k < n:
            raise ValueError(f"extra measurement at sample {m.k} is outside 0..{n - 1}")
        if not m.R > 0:
            raise ValueError(f"extra measurement at sample {m.k} has variance {m.R}; it must be > 0")
        by_k.setdefault(m.k, []).append(m)
    return by_k


def update(x: np.ndarray, P: np.ndarray, h: np.ndarray, z: float, R: float) -> tuple:
    """One scalar Kalman update; returns (x, P, y, S).

    The covariance uses the Joseph form, which keeps P symmetric and positive
    semi-definite under rounding even when P spans many orders of magnitude.
    """
    # y = z - H x
    y = z - h @ x
    # S = H P H' + R
    PHt = P @ h
    S = h @ PHt + R
    # K = P H' / S
    K = PHt / S
    # x = x + K y
    x = x + K * y
    # P = (I - K H) P (I - K H)' + K R K'
    I_KH = np.eye(len(x)) - np.outer(K, h)
    P = I_KH @ P @ I_KH.T + R * np.outer(K, K)
    return x, P, y, S


def run_filter(
    d: AxisDesign,
    z: np.ndarray,
    *,
    valid: np.ndarray | None = None,
    extras: Sequence[Measurement] = (),
    x0: np.ndarray | None = None,
    P0: np.ndarray | None = None,
    progress: bool | None = None,
) -> FilterResult:
    """Run the filter of design ``d`` over accelerations ``z`` [m/s^2].

    ``valid[k]`` False skips the acceleration update of sample k (predict only);
    ``extras`` are further scalar measurements (see :func:`position_fix`,
    :func:`zero_velocity`). ``x0``/``P0`` override the design's prior.
    """
    z = np.asarray(z, dtype=np.float64)
    n = len(z)
    if valid is None:
        valid = np.isfinite(z)
    else:
        valid = np.asarray(valid, dtype=bool) & np.isfinite(z)
    by_k = _group_extras(extras, n)
    F, Q, b = d.F, d.Q, d.b
    H = d.H[0]
    R = d.R

    x_prior = np.empty((n, 4))
    P_prior = np.empty((n, 4, 4))
    x_post = np.empty((n, 4))
    P_post = np.empty((n, 4, 4))
    ys = np.full(n, np.nan)
    Ss = np.full(n, np.nan)

    x = np.array(d.x0 if x0 is None else x0, dtype=np.float64)
    P = np.array(d.P0 if P0 is None else P0, dtype=np.float64)
    with Progress("filter", n, enabled=progress) as bar:
        for k in range(n):
            if k > 0:
                # x = F x + b
                x = F @ x + b
                # P = F P F' + Q
                P = F @ P @ F.T + Q
            x_prior[k] = x
            P_prior[k] = P
            if valid[k]:
                x, P, ys[k], Ss[k] = update(x, P, H, z[k], R)
            for m in by_k.get(k, ()):
                x, P, _, _ = update(x, P, np.asarray(m.h, dtype=np.float64), m.z, m.R)
            x_post[k] = x
            P_post[k] = P
            if k % 4096 == 0:
                bar.update(k)
    return FilterResult(x_prior, P_prior, x_post, P_post, ys, Ss)


def rts_smooth(d: AxisDesign, f: FilterResult, *, progress: bool | None = None) -> SmoothResult:
    """Rauch-Tung-Striebel smoother over the output of :func:`run_filter`.

    Index convention: F maps x[k] to x[k+1], and ``f.x_prior[k+1]`` is the
    prediction F x_post[k] + b (the forcing term b included), so for
    k = N-2 .. 0:

        C[k]  = P_post[k] F' inv(P_prior[k+1])
        xs[k] = x_post[k] + C[k] (xs[k+1] - x_prior[k+1])
        Ps[k] = P_post[k] + C[k] (Ps[k+1] - P_prior[k+1]) C[k]'

    starting from xs[N-1] = x_post[N-1], Ps[N-1] = P_post[N-1].

    P_prior spans many orders of magnitude (P_rr grows without bound while
    P_eps stays tiny), so C is computed by a solve on the diagonally
    equilibrated prior, whose condition number is that of its correlation
    matrix, rather than by an explicit inverse.
    """
    n = len(f)
    F = d.F
    xs = np.empty_like(f.x_post)
    Ps = np.empty_like(f.P_post)
    xs[-1] = f.x_post[-1]
    Ps[-1] = f.P_post[-1]
    with Progress("smooth", n, enabled=progress) as bar:
        for k in range(n - 2, -1, -1):
            Pp = f.P_prior[k + 1]
            # C = P_post F' inv(P_prior)  <=>  C' = inv(P_prior) F P_post
            s = np.sqrt(np.diag(Pp))
            s[s == 0] = 1.0
            Ct = np.linalg.solve(Pp / np.outer(s, s), (F @ f.P_post[k]) / s[:, None]) / s[:, None]
            C = Ct.T
            # xs = x_post + C (xs[k+1] - x_prior[k+1])
            xs[k] = f.x_post[k] + C @ (xs[k + 1] - f.x_prior[k + 1])
            # Ps = P_post + C (Ps[k+1] - P_prior[k+1]) C'
            Ps[k] = f.P_post[k] + C @ (Ps[k + 1] - Pp) @ Ct
            if k % 4096 == 0:
                bar.update(n - k)
    return SmoothResult(xs, Ps)


def bias_model(d: AxisDesign, n: int, powers: np.ndarray | None = None) -> np.ndarray:
    """The deterministic bias eps[k] of the model, k = 0 .. n-1 (the filter's prior mean). ``powers``: phi^k for
    k = 0 .. n-1 when the caller has them (axes that share phi share them: a power per sample costs more than the
    rest)."""
    if powers is None:
        powers = d.phi ** np.arange(n)
    # eps[k] = (c1 + c2) - c1 phi^k: the recursion eps[k+1] = phi eps[k] + b from eps[0] = c2
    return d.eps_mean - d.axis.c1 * powers


def double_integrate(d: AxisDesign, a: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Plain dead reckoning: integrate accelerations ``a`` twice with F's (r, u, a) block.

    Returns (N, 2) of [r, u] starting from rest at 0. Invalid samples hold the
    previous acceleration. This is the baseline the filter and smoother beat.
    """
    a = np.asarray(a, dtype=np.float64)
    if valid is not None:
        # forward-fill: each invalid sample takes the last valid one (0 before any)
        ok = np.asarray(valid, dtype=bool)
        last = np.maximum.accumulate(np.where(ok, np.arange(len(a)), -1))
        a = np.where(last >= 0, a[np.maximum(last, 0)], 0.0)
    Ts = d.Ts
    # u[k+1] = u[k] + Ts a[k];  r[k+1] = r[k] + Ts u[k] + Ts^2/2 a[k]
    u = np.concatenate(([0.0], np.cumsum(a[:-1]) * Ts))
    r = np.concatenate(([0.0], np.cumsum(Ts * u[:-1] + 0.5 * Ts * Ts * a[:-1])))
    return np.stack([r, u], axis=1)


def batch_update(X, P, H, z, R):
    """Scalar measurement updates of many independent (x, P) at once, one row each: (x, P, y, S).

    The update of :func:`run_filter`, vectorised over rows (the aids' replay for NIS in
    accelnav.estimate.consistency and the likelihood of accelnav.estimate.tune)."""
    # S = H P H' + R;  K = P H' / S;  x += K y;  P -= K H P
    Ph = np.einsum("nij,nj->ni", P, H)
    S = np.einsum("ni,ni->n", H, Ph) + R
    y = z - np.einsum("ni,ni->n", H, X)
    K = Ph / S[:, None]
    X = X + K * y[:, None]
    P = P - K[:, :, None] * Ph[:, None, :]
    return X, 0.5 * (P + np.swapaxes(P, 1, 2)), y, S
