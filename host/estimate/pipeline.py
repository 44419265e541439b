"""Run the filter and smoother over every axis of a run (no I/O here).

filter_run and smooth_run use the compiled filter and smoother of accelnav.estimate.fastsmooth, which
agree with the float64 reference (accelnav.estimate.kf, :func:`reference_filter_run`) to 1e-9.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from accelnav.estimate import engine
from accelnav.estimate.checks import check_run
from accelnav.estimate.kf import double_integrate, run_filter
from accelnav.model.design import axis_design
from accelnav.model.load import Model

if TYPE_CHECKING:  # consistency loads scipy: imported where it is used
    from accelnav.estimate.consistency import SmoothChecks


def filter_run(
    arrays: dict[str, np.ndarray], model: Model, *, progress: bool | None = None, covariances: bool = True
) -> dict[str, np.ndarray]:
    """Return ``arrays`` with the filter's posteriors (keys filt_x, filt_sd; with ``covariances`` also filt_P
    and the priors filt_x_prior, filt_P_prior).

    Compiled (accelnav.estimate.fastsmooth, whose filter agrees with the float64 reference
    accelnav.estimate.kf.run_filter to 1e-9; tests/estimate/test_smooth_output.py compares the two).
    ``progress`` is accepted for symmetry (the C is quick).
    """
    return _engine_run(engine.Job(stages=("filt",), covariances=covariances), arrays, model)


def _engine_run(job, arrays: dict[str, np.ndarray], model: Model) -> dict[str, np.ndarray]:
    """One run of the engine over arrays in memory, its outputs returned (one chunk)."""
    check_run(arrays, model, "smooth_run" if "smooth" in job.stages else "filter_run")
    return engine.run(model, engine.Source.of(arrays), job).arrays


def reference_filter_run(arrays: dict[str, np.ndarray], model: Model, *, progress: bool | None = None) -> dict:
    """The float64 reference filter (accelnav.estimate.kf.run_filter) over every axis: the oracle of
    :func:`filter_run` in tests, with today's full output keys."""
    results = [
        run_filter(axis_design(model, j), arrays["accel"][:, j], valid=~arrays["clipped"][:, j], progress=progress)
        for j in range(len(arrays["axis_names"]))
    ]
    out = dict(arrays)
    out["filt_x"] = np.stack([f.x_post for f in results])
    out["filt_P"] = np.stack([f.P_post for f in results])
    out["filt_x_prior"] = np.stack([f.x_prior for f in results])
    out["filt_P_prior"] = np.stack([f.P_prior for f in results])
    return out


def smooth_run(
    arrays: dict[str, np.ndarray],
    model: Model,
    *,
    progress: bool | None = None,
    fixes: list[list] | None = None,
    rest: np.ndarray | None = None,
    zupt_params=None,
    rest_sigma: np.ndarray | None = None,
    covariances: bool = True,
    warm_start: bool = False,
) -> dict[str, np.ndarray]:
    """Return ``arrays`` with the filter's and the RTS smoother's output (keys filt_*, smooth_*).

    ``warm_start``: the recording does not begin at power-on, so the bias prior is the settled c1 + c2
    rather than c2 (accelnav.model.edit.warm_started).

    Compiled (accelnav.estimate.fastsmooth): the plain path when there are no extras, else
    the general path. ``fixes[j]`` are position-fix measurements of axis
    column j (accelnav.estimate.fixes.read_fixes); ``rest`` is an (N,) mask of samples at
    rest (accelnav.estimate.zupt.rest_mask, or intervals from a file) that become
    zero-velocity updates, the same on every axis ((N,)) or per axis ((N, n_axes), from a
    ZUPT file), with ``rest_sigma`` (N, n_axes) their standard deviations (NaN: the
    params' sigma) (automatic rests are already gated per rest by rest_mask: no update is gated). The filter keys are
    rewritten too, so that filter and smoother saw the same measurements.
    Always: the means filt_x, smooth_x (n_axes, N, 4) and their standard deviations filt_sd, smooth_sd;
    with ``covariances`` also filt_P, smooth_P (n_axes, N, 4, 4) and the priors filt_x_prior, filt_P_prior.
    Adds ``zupt`` (N, n_axes) bool, the samples whose zero-velocity update
    was applied, ``fixes`` (M, 4) [t, axis column, position, sigma], and the normalised innovation
    squared y^2 / S of every aid the filter applied (accelnav.estimate.consistency): ``fix_nis`` (M,)
    beside ``fixes``, ``zupt_nis`` (K, 4) [t, axis column, NIS, 1 for the first update of its rest] (every update's
    here; a run file without ``--full`` keeps each rest's first: accelnav.data.runfile.compact).
    ``progress`` is accepted for symmetry with filter_run (the C is quick).
    """
    rests = None if rest is None else engine.Rests(zupt_params, mask=rest, sigma=rest_sigma)
    job = engine.Job(("filt", "smooth"), fixes, rests, covariances=covariances, checks=False, warm_start=warm_start)
    return _engine_run(job, arrays, model)


@dataclass(frozen=True)
class PositionErrors:
    """Position error against the truth of one axis, m."""

    axis: str
    method: str
    rms: float
    final: float
    max_abs: float


def dead_reckoning(arrays: dict[str, np.ndarray], model: Model) -> np.ndarray:
    """(n_axes, N, 2) [r, u] from plain double integration of the measured acceleration.

    No bias model: this is what a user gets by integrating the calibrated
    sensor output, the baseline the paper compares against.
    """
    return np.stack(
        [
            double_integrate(axis_design(model, j), arrays["accel"][:, j], valid=~arrays["clipped"][:, j])
            for j in range(len(arrays["axis_names"]))
        ]
    )


def error_rows(axis_names, truth_r: np.ndarray, estimates: dict[str, np.ndarray]) -> list[PositionErrors]:
    """Position errors of each named estimate against the truth, axis by axis.

    ``truth_r`` is (N, n_axes); each estimate is (n_axes, N), in the order the table lists them.
    """
    rows = []
    for j, name in enumerate(str(a) for a in axis_names):
        for method, r in estimates.items():
            e = r[j] - truth_r[:, j]
            rms = float(np.sqrt(np.mean(e**2)))
            rows.append(PositionErrors(name, method, rms, float(e[-1]), float(np.max(np.abs(e)))))
    return rows


def position_errors(arrays: dict[str, np.ndarray], model: Model) -> list[PositionErrors]:
    """Errors of plain double integration, the filter and the smoother, per axis (needs truth)."""
    if "r" not in arrays:
        return []
    return error_rows(arrays["axis_names"], arrays["r"], _position_estimates(arrays, model))


def _position_estimates(arrays: dict[str, np.ndarray], model: Model) -> dict[str, np.ndarray]:
    """(N, n_axes) positions of double integration, and of the filter and smoother where the run has them."""
    estimates = {"double integration": dead_reckoning(arrays, model)[:, :, 0]}
    if "filt_x" in arrays:
        estimates["filter"] = arrays["filt_x"][:, :, 0]
    if "smooth_x" in arrays:
        estimates["smoother"] = arrays["smooth_x"][:, :, 0]
        estimates.update(fix_baselines(arrays, model))
    return estimates


def format_errors(rows: list[PositionErrors]) -> str:
    """A plain-text table of :func:`position_errors`."""
    lines = [f"{'axis':<6}{'method':<24}{'rms [m]':>12}{'final [m]':>12}{'max |e| [m]':>13}"]
    for row in rows:
        lines.append(f"{row.axis:<6}{row.method:<24}{row.rms:12.3f}{row.final:12.3f}{row.max_abs:13.3f}")
    return "\n".join(lines)


@dataclass(frozen=True)
class StrideErrors:
    """Stride-length error of one estimate against the truth, over the strides of a walk."""

    method: str
    n_strides: int
    mean_length: float  # m, true
    mean_abs: float  # m
    rms: float  # m
    max_abs: float  # m

    @property
    def percent(self) -> float:
        """Mean absolute error as a share of the mean true stride length, %."""
        return 100.0 * self.mean_abs / self.mean_length


def stance_midpoints(stance: np.ndarray) -> np.ndarray:
    """Sample index at the middle of each stance (runs of True in ``stance``)."""
    from accelnav.estimate.zupt import intervals

    return np.array([(a + b - 1) // 2 for a, b in intervals(stance)], dtype=np.int64)


def stride_lengths(r: np.ndarray, mids: np.ndarray) -> np.ndarray:
    """Horizontal distance between consecutive stance midpoints; ``r`` is (N, n_axes)."""
    p = np.asarray(r)[mids]
    return np.linalg.norm(np.diff(p, axis=0), axis=1)


def stride_errors(arrays: dict[str, np.ndarray], estimates: dict[str, np.ndarray]) -> list[StrideErrors]:
    """Per-stride length error of each estimate ((n_axes, N) positions), from the true stance mask.

    A stride runs from the middle of one stance to the middle of the next;
    its length is the distance between the two foot positions, over all axes
    of the run (the horizontal plane for the walking scenario).
    """
    if "stance" not in arrays or "r" not in arrays:
        return []
    mids = stance_midpoints(arrays["stance"])
    if len(mids) < 2:
        return []
    true = stride_lengths(arrays["r"], mids)
    rows = []
    for method, r in estimates.items():
        e = stride_lengths(np.asarray(r).T, mids) - true
        rows.append(
            StrideErrors(
                method,
                len(e),
                float(true.mean()),
                float(np.mean(np.abs(e))),
                float(np.sqrt(np.mean(e**2))),
                float(np.max(np.abs(e))),
            )
        )
    return rows


def format_strides(rows: list[StrideErrors]) -> str:
    """A plain-text table of :func:`stride_errors`."""
    lines = [f"{'stride length':<26}{'strides':>8}{'mean |e| [m]':>14}{'[%]':>7}{'rms [m]':>10}{'max [m]':>10}"]
    for s in rows:
        lines.append(f"{s.method:<26}{s.n_strides:>8}{s.mean_abs:14.3f}{s.percent:7.1f}{s.rms:10.3f}{s.max_abs:10.3f}")
    return "\n".join(lines)


def stride_table(arrays: dict[str, np.ndarray], model: Model) -> list[StrideErrors]:
    """Stride errors of double integration, the filter and the smoother (needs truth with a stance mask)."""
    if "stance" not in arrays or "r" not in arrays:
        return []
    return stride_errors(arrays, _position_estimates(arrays, model))


BASELINES = ("fix interpolation", "fix-to-fix integration")


def rms_by_method(rows: list[PositionErrors]) -> dict[str, float]:
    """The rms position error of each method over all axes (``rows``: :func:`position_errors`)."""
    sq: dict[str, list[float]] = {}
    for row in rows:
        sq.setdefault(row.method, []).append(row.rms**2)
    return {k: float(np.sqrt(np.mean(v))) for k, v in sq.items()}


def fixes_per_axis(arrays: dict[str, np.ndarray]) -> list[list]:
    """The fixes of a smoothed run (its ``fixes`` rows) as measurements per axis column."""
    from accelnav.estimate.kf import position_fix

    out: list[list] = [[] for _ in arrays["axis_names"]]
    rows = np.asarray(arrays.get("fixes", np.zeros((0, 4)))).reshape(-1, 4)
    t = np.asarray(arrays["t"])
    for tf, j, r, s in rows:
        k = int(np.clip(np.searchsorted(t, tf), 0, len(t) - 1))
        if k > 0 and abs(t[k - 1] - tf) <= abs(t[k] - tf):
            k -= 1
        out[int(j)].append(position_fix(k, r, s))
    return out


def fix_baselines(
    arrays: dict[str, np.ndarray], model: Model, fixes: list[list] | None = None
) -> dict[str, np.ndarray]:
    """(n_axes, N) positions of the two fix-only baselines (accelnav.estimate.consistency); {} without fixes."""
    from accelnav.estimate.consistency import fix_to_fix_integration, interpolate_fixes

    fixes = fixes_per_axis(arrays) if fixes is None else fixes
    if not any(fixes):
        return {}
    t = arrays["t"]
    interp, f2f = [], []
    for j, fx in enumerate(fixes):
        interp.append(interpolate_fixes(t, fx))
        f2f.append(
            fix_to_fix_integration(axis_design(model, j), t, arrays["accel"][:, j], ~arrays["clipped"][:, j], fx)
        )
    return dict(zip(BASELINES, (np.stack(interp), np.stack(f2f)), strict=True))


@dataclass(frozen=True)
class Holdout:
    """RMS miss [m] of each method at fixes it was not given (every other fix of each axis left out)."""

    n: int  # fixes left out, all axes
    rms: dict[str, float]  # "smoother" and the BASELINES
    misses: dict[str, np.ndarray] | None = None  # |miss| at each held-out fix, per method

    def losses(self, baseline: str) -> int:
        """Held-out fixes the smoother misses by more than ``baseline``."""
        return int(np.sum(self.misses["smoother"] > self.misses[baseline]))

    def worse_than(self) -> list[str]:
        """The baselines that beat the smoother here: a larger rms miss, and more misses than a coin would give
        (a sign test at 5 %: one fix far off cannot decide it); none with fewer than HOLDOUT_MIN held out."""
        from accelnav.estimate.consistency import HOLDOUT_MIN, sign_test

        if self.n < HOLDOUT_MIN:
            return []
        return [b for b in BASELINES if self.rms["smoother"] > self.rms[b] and sign_test(self.losses(b), self.n) < 0.05]


def holdout(arrays: dict[str, np.ndarray], model: Model, fixes: list[list], **smooth_kw) -> Holdout | None:
    """Smoother and baselines given every other fix, scored on the others; None with < 3 fixes on every axis.

    ``smooth_kw`` (rest, zupt_params, rest_sigma) is passed to :func:`smooth_run`, so the smoother keeps
    its rests. Truth-free: the misses include the fixes' own noise, the same for every method.
    """
    if max((len(f) for f in fixes), default=0) < 3:
        return None
    given, held = [], []
    for fx in fixes:
        fx = sorted(fx, key=lambda m: m.k)
        if len(fx) < 3:
            given.append(fx)
            held.append([])
            continue
        given.append(fx[0::2])
        held.append(fx[1::2])
    base = {k: arrays[k] for k in ("t", "axis_names", "accel", "clipped")}
    sm = smooth_run(base, model, fixes=given, covariances=False, **smooth_kw)
    estimates = {"smoother": sm["smooth_x"][:, :, 0], **fix_baselines(base, model, given)}
    rms, misses = {}, {}
    for name, r in estimates.items():
        e = np.array([r[j, m.k] - m.z for j, h in enumerate(held) for m in h])
        rms[name] = float(np.sqrt(np.mean(np.square(e))))
        misses[name] = np.abs(e)
    return Holdout(sum(len(h) for h in held), rms, misses)


def smooth_checks(
    smoothed: dict, model, inputs: dict, fixes=None, *, review=None, tuned: bool = False, **smooth_kw
) -> SmoothChecks:
    """The consistency checks of a smoothed run (``smoothed``, from ``inputs`` with ``fixes`` and
    ``smooth_kw`` as :func:`accelnav.estimate.pipeline.smooth_run` took them); ``review``: the rests'
    re-examination (:func:`disagreeing_rests`) that chose ``smooth_kw``'s rests; ``tuned``: the model was
    fitted to this run."""
    from accelnav.estimate.consistency import ANCHOR_SD, NoAnchor, SmoothChecks, first_rest_nis, nis_check
    from accelnav.estimate.zupt import ZuptParams

    kinds = (("fixes", smoothed["fix_nis"]), ("rests", first_rest_nis(smoothed["zupt_nis"], smoothed["t"][0])))
    nis = tuple(nis_check(kind, v) for kind, v in kinds if len(v))
    h = None if fixes is None else holdout(inputs, model, fixes, **smooth_kw)
    no_anchor = None
    asked = smooth_kw.get("rest") is not None or review is not None
    if asked and not any(fixes or []):
        sd = smoothed["smooth_sd"][:, -1, 0]
        j = int(np.argmax(sd))
        if sd[j] > ANCHOR_SD:
            params = smooth_kw.get("zupt_params") or ZuptParams()
            used = np.flatnonzero(np.any(smoothed["zupt"], axis=1))
            last = float(smoothed["t"][used[-1]]) if len(used) else None
            no_anchor = NoAnchor(float(sd[j]), str(smoothed["axis_names"][j]), params.start_s, last)
    return SmoothChecks(nis, h, review, tuned, no_anchor)


def truth_versus_baselines(rows: list[PositionErrors], tune_helps: bool) -> str:
    """With truth and fixes: a line if the smoother is worse than a fix-only baseline (rms over the axes), else
    ''; ``tune_helps``: SmoothChecks.tune_helps, the only case in which it advises --tune."""
    rms = rms_by_method(rows)
    worse = [b for b in BASELINES if b in rms and rms["smoother"] > rms[b]]
    if not worse:
        return ""
    return (
        f"against the truth the smoother ({rms['smoother']:.3g} m rms) is worse than {' and '.join(worse)} "
        f"({min(rms[b] for b in worse):.3g} m): its model does not fit this recording"
        + (": try --tune" if tune_helps else "")
    )


def disagreeing_rests(inputs: dict, model, rest: np.ndarray, *, fixes=None, params=None, rest_sigma=None, stands=()):
    """The rests of ``rest`` ((N,) or (N, n_axes) mask) that disagree with the fixes and the other rests (see
    accelnav.estimate.consistency): a consistency.RestReview whose ``dropped`` name them, with their statistics,
    and whose ``kept`` is the mask without them. ``inputs`` (t, axis_names, accel, clipped), ``model``,
    ``fixes`` (per axis), ``params`` (ZuptParams) and ``rest_sigma`` as :func:`smooth_run` takes them.
    ``stands``: (start, stop) spans of rests decided on evidence of their own that the smoother's model does
    not weigh (the kinematics of a stop: accelnav.estimate.rests' "still stand"; the engine gives them where
    there are no fixes); the rests holding one are tested against the fixes but not dropped against the other
    rests (without fixes, a model too stiff for a car's 40 s drive called a real stop after a braking from
    23 m/s "6.3 m/s").
    Bounded: one smoothing with the fixes, then at most consistency.REVIEW_SMOOTHINGS; none without rests. At most
    two whole-run smoothings are held at once (the one with ``kept``'s rests and one leave-one-out); the last made
    with the rests kept comes back in ``RestReview.smoothed`` (None when a rest was dropped after it)."""
    from accelnav.estimate import zupt
    from accelnav.estimate.consistency import (
        REVIEW_MEDIAN_MIN,
        REVIEW_SMOOTHINGS,
        REVIEW_SUSPECTS,
        RestReview,
        RestTest,
        chi2_median,
        first_update_nis,
        rest_bound,
        rest_tests,
    )

    params = zupt.ZuptParams() if params is None else params
    n, n_axes = np.asarray(inputs["accel"]).shape
    r = np.asarray(rest, dtype=bool)
    kept = np.array(np.broadcast_to(r[:, None] if r.ndim == 1 else r, (n, n_axes)))
    sigma = np.full((n, n_axes), float(params.sigma))
    if rest_sigma is not None:
        given = np.asarray(rest_sigma, dtype=np.float64)
        sigma = np.where(np.isfinite(given), given, sigma)
    updates = np.zeros((n, n_axes), dtype=bool)
    for j in range(n_axes):
        updates[zupt.update_samples(kept[:, j], model, params), j] = True
    rests = zupt.intervals(kept.any(axis=1))
    base = {k: inputs[k] for k in ("t", "axis_names", "accel", "clipped")}
    dropped: list[RestTest] = []
    smoothings = 0

    def drop(tests: list[RestTest]) -> None:
        for t in tests:
            kept[t.start : t.stop] = False
            updates[t.start : t.stop] = False
            dropped.append(t)

    if fixes is not None and any(fixes) and rests:
        sm = smooth_run(base, model, fixes=fixes, covariances=False)
        smoothings += 1
        inflate = max(1.0, float(np.mean(sm["fix_nis"]))) if len(sm["fix_nis"]) else 1.0
        drop([t for t in rest_tests(sm, rests, updates, sigma, "the fixes", len(rests), var_scale=inflate) if t.fails])
        del sm  # not held while the next smoothing is made
    complete, undecided = True, False
    sm = None  # the smoothing with ``kept``'s rests; None once a rest it holds is dropped
    while True:
        left = zupt.intervals(kept.any(axis=1))
        if not left:
            break
        sm = smooth_run(base, model, fixes=fixes, rest=kept, zupt_params=params, rest_sigma=rest_sigma,
                        covariances=False)  # fmt: skip
        smoothings += 1
        forward = first_update_nis(sm, left)
        # relative to the median rest where there are enough rests for a median to say what is usual
        scale = max(1.0, float(np.median(forward)) / chi2_median(n_axes)) if len(left) >= REVIEW_MEDIAN_MIN else 1.0
        bound = rest_bound(n_axes, len(rests))
        own = {i for i, (a, b) in enumerate(left) if any(sa < b and a < sb for sa, sb in stands)}
        order = [i for i in np.argsort(-forward)[:REVIEW_SUSPECTS] if forward[i] / scale > bound and i not in own]
        if not order:
            break
        # witnesses: the rests, and the filter's u = 0 at the start where a rest there confirms it; of two that
        # disagree, neither can be called wrong
        if len(left) + (left[0][0] == 0) < 3:
            undecided = True
            break
        if smoothings + len(order) > REVIEW_SMOOTHINGS:
            complete = False
            break
        tests = []
        for i in order:
            a, b = left[i]
            without = kept.copy()
            without[a:b] = False
            loo = smooth_run(base, model, fixes=fixes, rest=without, zupt_params=params, rest_sigma=rest_sigma,
                             covariances=False)  # fmt: skip
            smoothings += 1
            tests += rest_tests(loo, [(a, b)], updates, sigma, "the other rests", len(rests), scale)
            del loo  # not held while the next one is made
        worst = max(tests, key=lambda t: t.chi2)
        if not worst.fails:
            break
        drop([worst])
        sm = None  # it held the rest just dropped: freed before the next smoothing
    return RestReview(len(rests), tuple(dropped), smoothings, complete, kept, np.asarray(inputs["t"]), undecided,
                      smoothed=sm)  # fmt: skip
