"""Plots a person would look at (matplotlib, Agg backend, PNG files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accelnav.data.runfile import state_sd
from accelnav.estimate.pipeline import dead_reckoning
from accelnav.fileio import atomic_output
from accelnav.model.load import Model


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _band(ax, t, x, sd, color, label, ls="-"):
    ax.plot(t, x, color=color, lw=1.2, ls=ls, label=label)
    ax.fill_between(t, x - sd, x + sd, color=color, alpha=0.18, lw=0)


def plot_run(arrays: dict[str, np.ndarray], model: Model, path: str | Path, title: str = "") -> Path:
    """Position, velocity and bias of every axis: truth, double integration, filter and smoother (+-1 sigma);
    on the velocity row, the detector's accepted and refused rests when the run has ``zupt_candidates``."""
    plt = _pyplot()
    t, start = _from_start(arrays["t"])
    names = [str(a) for a in arrays["axis_names"]]
    plain = dead_reckoning(arrays, model)
    fig, axes = plt.subplots(3, len(names), figsize=(6.5 * len(names), 9.5), sharex=True, squeeze=False)
    rows = (("position r [m]", 0), ("velocity u [m/s]", 1), ("bias eps [m/s^2]", 3))
    truth_keys = ("r", "u", "a", "eps")
    for j, name in enumerate(names):
        for row, (label, i) in enumerate(rows):
            ax = axes[row, j]
            if truth_keys[i] in arrays:
                ax.plot(t, arrays[truth_keys[i]][:, j], color="black", lw=1.6, label="truth")
            if i < 2:
                dr = ax.plot(t, plain[j, :, i], color="tab:gray", lw=1.0, ls="--", label="double integration")[0]
            # the smoother underneath, the filter dashed on top: they coincide where no future data helps
            for stage, color, lab, ls in (("smooth", "tab:red", "smoother", "-"), ("filt", "tab:blue", "filter", "--")):
                if f"{stage}_x" in arrays:
                    x = arrays[f"{stage}_x"][j, :, i]
                    sd = state_sd(arrays, stage)[j, :, i]
                    _band(ax, t, x, sd, color, f"{lab} +-1 sigma", ls)
            if i == 1:
                _rest_marks(ax, arrays, start)
            if i < 2 and "r" not in arrays:
                stage = "smooth" if "smooth_x" in arrays else "filt"
                if f"{stage}_x" in arrays:
                    _clip_to_track(ax, dr, arrays[f"{stage}_x"][j, :, i], state_sd(arrays, stage)[j, :, i])
            if i < 2 and "r" in arrays:
                # keep the truth readable when dead reckoning runs away
                span = np.ptp(arrays[truth_keys[i]][:, j])
                lo = arrays[truth_keys[i]][:, j].min() - 0.5 * span - 1.0
                hi = arrays[truth_keys[i]][:, j].max() + 0.5 * span + 1.0
                ax.set_ylim(lo, hi)
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
            if row == 0:
                ax.set_title(f"axis {name}")
        axes[-1, j].set_xlabel(_TIME_LABEL)
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(title or f"accelnav: {model.name}")
    fig.tight_layout()
    path = Path(path)
    with atomic_output(path, flag="--plots") as fh:  # a plot appears whole or not at all
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return path


_TIME_LABEL = "time from the recording's start [s]"


def _from_start(t: np.ndarray) -> tuple[np.ndarray, float]:
    """Time from the first sample, and that sample's time: a recording stamped in Unix seconds would
    otherwise label its axis "+1.73253e9" and hide the seconds that matter."""
    start = float(t[0]) if len(t) else 0.0
    return t - start, start


def _clip_to_track(ax, line, x: np.ndarray, sd: np.ndarray) -> None:
    """Limit the y range to an estimate's track (+-1 sigma, with a margin) so that double integration,
    which runs away quadratically, does not flatten it; the curve's label says when it leaves the plot."""
    lo, hi = float(np.min(x - sd)), float(np.max(x + sd))
    pad = 0.15 * (hi - lo) + 1e-3
    lo, hi = lo - pad, hi + pad
    y = np.asarray(line.get_ydata(), dtype=np.float64)
    ax.set_ylim(lo, hi)
    if len(y) and (y.min() < lo or y.max() > hi):
        worst = float(np.max(np.abs(y)))
        line.set_label(f"{line.get_label()} (leaves the plot, reaches {worst:.3g})")


def _axis_columns(plt, n_axes: int, title: str):
    fig, axes = plt.subplots(1, n_axes, figsize=(6.5 * n_axes, 4.6), squeeze=False)
    fig.suptitle(title)
    return fig, axes[0]


def _save(plt, fig, path: Path) -> Path:
    fig.tight_layout()
    with atomic_output(path, flag="--plots") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return path


def _rest_marks(ax, arrays, start: float = 0.0) -> None:
    """The detector's candidate rests (key ``zupt_candidates``, rows [start_s, end_s, accepted]): accepted ones
    shaded green, refused ones hatched red, so that a refused stop or an accepted 'rest' at speed shows."""
    rows = arrays.get("zupt_candidates")
    if rows is None or not len(rows):
        return
    first = {True: True, False: True}
    for t0, t1, acc in np.asarray(rows, dtype=np.float64).reshape(-1, 3):
        ok = bool(acc)
        label = ("rest accepted" if ok else "rest refused") if first[ok] else None
        first[ok] = False
        t0, t1 = t0 - start, t1 - start
        if ok:
            ax.axvspan(t0, t1, color="tab:green", alpha=0.15, lw=0, label=label)
        else:
            ax.axvspan(t0, t1, facecolor="none", edgecolor="tab:red", hatch="///", alpha=0.5, lw=0, label=label)


def _marks(ax, arrays, j, t, start: float = 0.0):
    """Shade the samples whose zero-velocity update was applied; dots for position fixes."""
    if "zupt" in arrays and arrays["zupt"][:, j].any():
        from accelnav.estimate.zupt import intervals

        # an update every few samples: join the runs with gaps up to a second
        z = arrays["zupt"][:, j].astype(float)
        w = max(1, int(round(1.0 / max(t[1] - t[0], 1e-9)))) if len(t) > 1 else 1
        joined = np.convolve(z, np.ones(w), mode="same") > 0
        for i, (a, b) in enumerate(intervals(joined)):
            ax.axvspan(
                t[a], t[b - 1], color="tab:green", alpha=0.08, lw=0, label="zero-velocity updates" if i == 0 else None
            )
    if "fixes" in arrays and len(arrays["fixes"]):
        f = arrays["fixes"][arrays["fixes"][:, 1] == j]
        if len(f):
            ax.errorbar(
                f[:, 0] - start,
                f[:, 2],
                yerr=f[:, 3],
                fmt="o",
                color="tab:purple",
                ms=4,
                label="position fix +-1 sigma",
            )


def plot_smoothing(arrays: dict[str, np.ndarray], model: Model, folder: str | Path) -> list[Path]:
    """The paper's figures for a smoothed run, one PNG each, every axis side by side.

    * fig10_bias.png: the bias estimate of the filter and of the smoother (+-1
      sigma) beside the model's mean bias eps(t) (and the truth when simulated).
    * fig11_position_filter.png: position from plain double integration and
      from the filter (+-1 sigma), and the truth.
    * fig12_position_smoother.png: position from the filter and the smoother
      (+-1 sigma), and the truth; zero-velocity updates shaded, fixes as dots, and the detector's
      candidate rests (accepted green, refused hatched red) when ``zupt_candidates`` is present.
    """
    from accelnav.estimate.kf import bias_model
    from accelnav.model.design import axis_design

    plt = _pyplot()
    folder = Path(folder)
    t, start = _from_start(arrays["t"])
    names = [str(a) for a in arrays["axis_names"]]
    plain = dead_reckoning(arrays, model)
    has_truth = "r" in arrays
    paths = []

    fig, axes = _axis_columns(plt, len(names), f"Bias estimate (cf. paper Fig. 10): {model.name}")
    for j, ax in enumerate(axes):
        d = axis_design(model, j)
        if has_truth:
            ax.plot(t, arrays["eps"][:, j], color="black", lw=1.4, label="truth")
        ax.plot(t, bias_model(d, len(t)), color="tab:gray", ls=":", lw=1.2, label="model mean c1(1-exp(-t/T))+c2")
        for stage, color, lab, ls in (("smooth", "tab:red", "smoother", "-"), ("filt", "tab:blue", "filter", "--")):
            _band(
                ax,
                t,
                arrays[f"{stage}_x"][j, :, 3],
                state_sd(arrays, stage)[j, :, 3],
                color,
                f"{lab} +-1 sigma",
                ls,
            )
        ax.set_title(f"axis {names[j]}")
        ax.set_xlabel(_TIME_LABEL)
        ax.set_ylabel("bias eps [m/s^2]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    paths.append(_save(plt, fig, folder / "fig10_bias.png"))

    fig, axes = _axis_columns(plt, len(names), f"Position, filter (cf. paper Fig. 11): {model.name}")
    for j, ax in enumerate(axes):
        if has_truth:
            ax.plot(t, arrays["r"][:, j], color="black", lw=1.4, label="truth")
        dr = ax.plot(t, plain[j, :, 0], color="tab:gray", ls="--", lw=1.0, label="double integration")[0]
        _band(ax, t, arrays["filt_x"][j, :, 0], state_sd(arrays, "filt")[j, :, 0], "tab:blue", "filter +-1 sigma")
        if not has_truth:
            _clip_to_track(ax, dr, arrays["filt_x"][j, :, 0], state_sd(arrays, "filt")[j, :, 0])
        _marks(ax, arrays, j, t, start)
        ax.set_title(f"axis {names[j]}")
        ax.set_xlabel(_TIME_LABEL)
        ax.set_ylabel("position r [m]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    paths.append(_save(plt, fig, folder / "fig11_position_filter.png"))

    fig, axes = _axis_columns(plt, len(names), f"Position, smoother (cf. paper Fig. 12): {model.name}")
    for j, ax in enumerate(axes):
        ref = arrays["r"][:, j] if has_truth else arrays["smooth_x"][j, :, 0]
        if has_truth:
            ax.plot(t, ref, color="black", lw=1.4, label="truth")
        _band(
            ax,
            t,
            arrays["filt_x"][j, :, 0],
            state_sd(arrays, "filt")[j, :, 0],
            "tab:blue",
            "filter +-1 sigma",
            "--",
        )
        _band(ax, t, arrays["smooth_x"][j, :, 0], state_sd(arrays, "smooth")[j, :, 0], "tab:red", "smoother +-1 sigma")
        _marks(ax, arrays, j, t, start)
        _rest_marks(ax, arrays, start)
        span = np.ptp(ref) if len(ref) else 1.0
        ax.set_ylim(ref.min() - 0.5 * span - 1.0, ref.max() + 0.5 * span + 1.0)  # the filter may run far away
        ax.set_title(f"axis {names[j]}")
        ax.set_xlabel(_TIME_LABEL)
        ax.set_ylabel("position r [m]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    paths.append(_save(plt, fig, folder / "fig12_position_smoother.png"))
    return paths


pyplot = _pyplot  # public: the other figure modules draw with the same backend set-up


def plot_estimates(
    t: np.ndarray, axis_names, truth_r: np.ndarray, estimates: dict[str, np.ndarray], folder: str | Path, title: str
) -> list[Path]:
    """Exactly the rows of a position-error table (:func:`accelnav.estimate.pipeline.error_rows` of the same
    ``estimates``: name -> (n_axes, N) positions), nothing else, every axis side by side:

    * position.png: the truth and each estimate;
    * position_error.png: each estimate's error against the truth, its rms in the legend as in the table.

    The y range is the truth's (position) or the other estimates' (error) when one estimate runs away (double
    integration does): its label then says how far it goes."""
    plt = _pyplot()
    folder = Path(folder)
    t, _ = _from_start(np.asarray(t, dtype=np.float64))
    names = [str(a) for a in axis_names]
    colors = ("tab:gray", "tab:blue", "tab:purple", "tab:red", "tab:orange", "tab:green")
    paths = []
    for kind, fname in (("position", "position.png"), ("error", "position_error.png")):
        fig, axes = _axis_columns(plt, len(names), f"{title}: {'position' if kind == 'position' else 'error'}")
        for j, ax in enumerate(axes):
            truth = truth_r[:, j]
            curves = {m: (r[j] - truth if kind == "error" else r[j]) for m, r in estimates.items()}
            if kind == "position":
                ax.plot(t, truth, color="black", lw=1.6, label="truth")
                span = float(np.ptp(truth)) if len(truth) else 1.0
                lo, hi = float(truth.min()) - 0.5 * span - 1.0, float(truth.max()) + 0.5 * span + 1.0
            else:
                ax.axhline(0.0, color="black", lw=0.8)
                worst = max(curves, key=lambda m: float(np.max(np.abs(curves[m]))))
                rest = [np.max(np.abs(c)) for m, c in curves.items() if m != worst] or [1.0]
                lim = 1.5 * float(max(rest)) + 1e-3
                lo, hi = -lim, lim
            for k, (m, y) in enumerate(curves.items()):
                rms = float(np.sqrt(np.mean((estimates[m][j] - truth) ** 2)))
                label = f"{m} (rms {rms:.3g} m)"
                if len(y) and (y.min() < lo or y.max() > hi):
                    label += f", leaves the plot, reaches {float(np.max(np.abs(y))):.3g} m"
                ax.plot(t, y, color=colors[k % len(colors)], lw=1.2, ls="--" if k == 0 else "-", label=label)
            ax.set_ylim(lo, hi)
            ax.set_title(f"axis {names[j]}")
            ax.set_xlabel(_TIME_LABEL)
            ax.set_ylabel("position r [m]" if kind == "position" else "error against the truth [m]")
            ax.grid(True, alpha=0.3)
            ax.legend(loc="best", fontsize=8)
        paths.append(_save(plt, fig, folder / fname))
    return paths
