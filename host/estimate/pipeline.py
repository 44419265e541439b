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
    beside ``fixes``, ``zupt_nis`` (K, 4) [t, axis column, NIS, 1 for the first update of its rest].
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

    def worse_than(self) -> list[str]:
        """The baselines that beat the smoother here."""
        return [b for b in BASELINES if self.rms["smoother"] > self.rms[b]]


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
    rms = {}
    for name, r in estimates.items():
        e = [r[j, m.k] - m.z for j, h in enumerate(held) for m in h]
        rms[name] = float(np.sqrt(np.mean(np.square(e))))
    return Holdout(sum(len(h) for h in held), rms)


def smooth_checks(smoothed: dict, model, inputs: dict, fixes=None, **smooth_kw) -> SmoothChecks:
    """The consistency checks of a smoothed run (``smoothed``, from ``inputs`` with ``fixes`` and
    ``smooth_kw`` as :func:`accelnav.estimate.pipeline.smooth_run` took them)."""
    from accelnav.estimate.consistency import SmoothChecks, nis_check

    first = smoothed["zupt_nis"][:, 3] > 0  # each rest's first update (see smooth_run)
    kinds = (("fixes", smoothed["fix_nis"]), ("rests", smoothed["zupt_nis"][first, 2]))
    nis = tuple(nis_check(kind, v) for kind, v in kinds if len(v))
    h = None if fixes is None else holdout(inputs, model, fixes, **smooth_kw)
    return SmoothChecks(nis, h)
