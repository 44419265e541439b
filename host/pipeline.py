"""Run the reference filter and smoother over every axis of a run (no I/O here)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from codegen.design import axis_design
from codegen.model import Model

from .kf import FilterResult, SmoothResult, double_integrate, rts_smooth, run_filter


def filter_run(arrays: dict[str, np.ndarray], model: Model, *, progress: bool | None = None) -> dict[str, np.ndarray]:
    """Return ``arrays`` with the filter's posteriors and priors added (keys filt_*)."""
    results = [
        run_filter(axis_design(model, j), arrays["accel"][:, j], valid=~arrays["clipped"][:, j], progress=progress)
        for j in range(len(arrays["axis_names"]))
    ]
    out = dict(arrays)
    out["filt_x"] = np.stack([f.x_post for f in results])
    out["filt_P"] = np.stack([f.P_post for f in results])
    out["filt_x_prior"] = np.stack([f.x_prior for f in results])
    out["filt_P_prior"] = np.stack([f.P_prior for f in results])
    for key in ("smooth_x", "smooth_P"):  # a new filter run makes an old smoothing stale
        out.pop(key, None)
    return out


def _filter_result(arrays: dict[str, np.ndarray], j: int) -> FilterResult:
    n = len(arrays["t"])
    nan = np.full(n, np.nan)
    return FilterResult(
        arrays["filt_x_prior"][j], arrays["filt_P_prior"][j], arrays["filt_x"][j], arrays["filt_P"][j], nan, nan
    )


def smooth_run(arrays: dict[str, np.ndarray], model: Model, *, progress: bool | None = None) -> dict[str, np.ndarray]:
    """Return ``arrays`` with the RTS smoother's output added (keys smooth_*); filters first if needed."""
    if "filt_x_prior" not in arrays:
        arrays = filter_run(arrays, model, progress=progress)
    results: list[SmoothResult] = [
        rts_smooth(axis_design(model, j), _filter_result(arrays, j), progress=progress)
        for j in range(len(arrays["axis_names"]))
    ]
    out = dict(arrays)
    out["smooth_x"] = np.stack([s.x for s in results])
    out["smooth_P"] = np.stack([s.P for s in results])
    return out


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


def position_errors(arrays: dict[str, np.ndarray], model: Model) -> list[PositionErrors]:
    """Errors of plain double integration, the filter and the smoother, per axis (needs truth)."""
    if "r" not in arrays:
        return []
    plain = dead_reckoning(arrays, model)
    rows = []
    for j, name in enumerate(str(a) for a in arrays["axis_names"]):
        truth = arrays["r"][:, j]
        estimates = {"double integration": plain[j, :, 0]}
        if "filt_x" in arrays:
            estimates["filter"] = arrays["filt_x"][j, :, 0]
        if "smooth_x" in arrays:
            estimates["smoother"] = arrays["smooth_x"][j, :, 0]
        for method, r in estimates.items():
            e = r - truth
            rms = float(np.sqrt(np.mean(e**2)))
            rows.append(PositionErrors(name, method, rms, float(e[-1]), float(np.max(np.abs(e)))))
    return rows


def combine_errors(runs: list[list[PositionErrors]]) -> list[PositionErrors]:
    """Root mean square of each figure over several runs (rows matched by axis and method)."""
    out = []
    for i, row in enumerate(runs[0]):
        rows = [r[i] for r in runs]

        def rms(field: str, rows=rows) -> float:
            return float(np.sqrt(np.mean([getattr(r, field) ** 2 for r in rows])))

        out.append(PositionErrors(row.axis, row.method, rms("rms"), rms("final"), rms("max_abs")))
    return out


def format_errors(rows: list[PositionErrors]) -> str:
    """A plain-text table of :func:`position_errors`."""
    lines = [f"{'axis':<6}{'method':<20}{'rms [m]':>12}{'final [m]':>12}{'max |e| [m]':>13}"]
    for row in rows:
        lines.append(f"{row.axis:<6}{row.method:<20}{row.rms:12.3f}{row.final:12.3f}{row.max_abs:13.3f}")
    return "\n".join(lines)
