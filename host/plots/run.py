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


def _band(ax, t, x, lo, hi, color, label, ls="-"):
    ax.plot(t, x, color=color, lw=1.2, ls=ls, label=label)
    ax.fill_between(t, lo, hi, color=color, alpha=0.18, lw=0)


class _Samples:
    """What the figures draw, from a run held in memory: every sample."""

    def __init__(self, arrays: dict[str, np.ndarray], model: Model) -> None:
        self.arrays, self.model = arrays, model
        self.t, self.start = _from_start(arrays["t"])
        self.names = [str(a) for a in arrays["axis_names"]]
        self._plain = None

    def has(self, key: str) -> bool:
        return key in self.arrays

    def truth(self, key: str, j: int) -> np.ndarray:
        return self.arrays[key][:, j]

    def dead_reckoning(self, j: int, i: int) -> np.ndarray:
        if self._plain is None:
            self._plain = dead_reckoning(self.arrays, self.model)
        return self._plain[j, :, i]

    def x(self, stage: str, j: int, i: int) -> np.ndarray:
        return self.arrays[f"{stage}_x"][j, :, i]

    def band(self, stage: str, j: int, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, x - sd, x + sd) of state i of axis j."""
        x, sd = self.x(stage, j, i), state_sd(self.arrays, stage)[j, :, i]
        return x, x - sd, x + sd

    def bias_mean(self, j: int) -> np.ndarray:
        from accelnav.estimate.kf import bias_model
        from accelnav.model.design import axis_design

        return bias_model(axis_design(self.model, j), len(self.t))

    def zupt_spans(self, j: int) -> list[tuple[float, float]]:
        """Where zero-velocity updates were applied: an update every few samples, so runs joined over gaps up to
        a second."""
        arrays, t = self.arrays, self.t
        if "zupt" not in arrays or not arrays["zupt"][:, j].any():
            return []
        from accelnav.estimate.zupt import intervals

        z = arrays["zupt"][:, j].astype(float)
        w = max(1, int(round(1.0 / max(t[1] - t[0], 1e-9)))) if len(t) > 1 else 1
        joined = np.convolve(z, np.ones(w), mode="same") > 0
        return [(t[a], t[b - 1]) for a, b in intervals(joined)]

    def small(self, key: str):
        return self.arrays.get(key)


class _Envelope:
    """What the figures draw, from a chunked run's envelope (accelnav.estimate.envelope.Envelope): per bin of
    samples (narrower than a pixel column) each series' min then max, and each band's lowest and highest."""

    def __init__(self, env, axis_names) -> None:
        self.env = env
        self.start = float(env.lo["t"][0])
        self.t = env.times() - self.start
        self.names = [str(a) for a in axis_names]

    def has(self, key: str) -> bool:
        return f"{key}/0" in self.env

    def truth(self, key: str, j: int) -> np.ndarray:
        return self.env.lines(f"{key}/{j}")

    def dead_reckoning(self, j: int, i: int) -> np.ndarray:
        return self.env.lines(f"dr/{j}")[:, i]

    def x(self, stage: str, j: int, i: int) -> np.ndarray:
        return self.env.lines(f"{stage}_x/{j}")[:, i]

    def band(self, stage: str, j: int, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        lo, hi = self.env.lo[f"{stage}_lo/{j}"][:, i], self.env.hi[f"{stage}_hi/{j}"][:, i]
        return self.x(stage, j, i), np.repeat(lo, 2), np.repeat(hi, 2)

    def bias_mean(self, j: int) -> np.ndarray:
        return self.env.lines(f"bias/{j}")

    def zupt_spans(self, j: int) -> list[tuple[float, float]]:
        if "zupt" not in self.env:
            return []
        from accelnav.estimate.zupt import intervals

        first, last = self.t[0::2], self.t[1::2]
        return [(first[a], last[b - 1]) for a, b in intervals(self.env.hi["zupt"][:, j] > 0)]

    def small(self, key: str):
        return self.env.extra.get(key)


def plot_outcome(outcome, folder: str | Path) -> list[Path]:
    """smooth.png and the paper's figures of a smoothing (accelnav.estimate.engine.Outcome): from its arrays
    when the run was one chunk in memory, else from the envelope kept while its chunks were written."""
    folder = Path(folder)
    if outcome.arrays is not None:
        view = _Samples(outcome.arrays, outcome.model)
    elif outcome.envelope is not None:
        view = _Envelope(outcome.envelope, outcome.axis_names)
    else:
        raise ValueError("plot_outcome: a chunked run keeps what its figures draw only when asked (Job(envelope=True))")
    return [_draw_run(view, outcome.model, folder / "smooth.png"), *_draw_smoothing(view, outcome.model, folder)]


def plot_run(arrays: dict[str, np.ndarray], model: Model, path: str | Path, title: str = "") -> Path:
    """Position, velocity and bias of every axis: truth, double integration, filter and smoother (+-1 sigma);
    on the velocity row, the detector's accepted and refused rests when the run has ``zupt_candidates``."""
    return _draw_run(_Samples(arrays, model), model, path, title)


def _draw_run(view, model: Model, path: str | Path, title: str = "") -> Path:
    plt = _pyplot()
    t, names = view.t, view.names
    fig, axes = plt.subplots(3, len(names), figsize=(6.5 * len(names), 9.5), sharex=True, squeeze=False)
    rows = (("position r [m]", 0), ("velocity u [m/s]", 1), ("bias eps [m/s^2]", 3))
    truth_keys = ("r", "u", "a", "eps")
    for j, name in enumerate(names):
        for row, (label, i) in enumerate(rows):
            ax = axes[row, j]
            if view.has(truth_keys[i]):
                ax.plot(t, view.truth(truth_keys[i], j), color="black", lw=1.6, label="truth")
            if i < 2:
                dr = ax.plot(t, view.dead_reckoning(j, i), color="tab:gray", lw=1.0, ls="--",
                             label="double integration")[0]  # fmt: skip
            # the smoother underneath, the filter dashed on top: they coincide where no future data helps
            for stage, color, lab, ls in (("smooth", "tab:red", "smoother", "-"), ("filt", "tab:blue", "filter", "--")):
                if view.has(f"{stage}_x"):
                    _band(ax, t, *view.band(stage, j, i), color, f"{lab} +-1 sigma", ls)
            if i == 1:
                _rest_marks(ax, view.small("zupt_candidates"), view.start)
            if i < 2 and not view.has("r"):
                stage = "smooth" if view.has("smooth_x") else "filt"
                if view.has(f"{stage}_x"):
                    _clip_to_track(ax, dr, *view.band(stage, j, i)[1:])
            if i < 2 and view.has("r"):
                # keep the truth readable when dead reckoning runs away
                truth = view.truth(truth_keys[i], j)
                span = np.nanmax(truth) - np.nanmin(truth)
                ax.set_ylim(np.nanmin(truth) - 0.5 * span - 1.0, np.nanmax(truth) + 0.5 * span + 1.0)
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


def _clip_to_track(ax, line, lower: np.ndarray, upper: np.ndarray) -> None:
    """Limit the y range to an estimate's track (its +-1 sigma band ``lower``..``upper``, with a margin) so that
    double integration, which runs away quadratically, does not flatten it; the curve's label says when it
    leaves the plot."""
    lo, hi = float(np.nanmin(lower)), float(np.nanmax(upper))
    pad = 0.15 * (hi - lo) + 1e-3
    lo, hi = lo - pad, hi + pad
    y = np.asarray(line.get_ydata(), dtype=np.float64)
    ax.set_ylim(lo, hi)
    if len(y) and (np.nanmin(y) < lo or np.nanmax(y) > hi):
        worst = float(np.nanmax(np.abs(y)))
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


def _rest_marks(ax, rows, start: float = 0.0) -> None:
    """The detector's candidate rests (``rows`` of the run's ``zupt_candidates``: [start_s, end_s, accepted]):
    accepted ones shaded green, refused ones hatched red, so that a refused stop or an accepted 'rest' at speed
    shows."""
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


def _marks(ax, view, j):
    """Shade the samples whose zero-velocity update was applied; dots for position fixes."""
    for i, (a, b) in enumerate(view.zupt_spans(j)):
        ax.axvspan(a, b, color="tab:green", alpha=0.08, lw=0, label="zero-velocity updates" if i == 0 else None)
    fixes = view.small("fixes")
    if fixes is not None and len(fixes):
        f = fixes[fixes[:, 1] == j]
        if len(f):
            ax.errorbar(
                f[:, 0] - view.start,
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
    return _draw_smoothing(_Samples(arrays, model), model, folder)


def _draw_smoothing(view, model: Model, folder: str | Path) -> list[Path]:
    plt = _pyplot()
    folder = Path(folder)
    t, names = view.t, view.names
    has_truth = view.has("r")
    paths = []

    fig, axes = _axis_columns(plt, len(names), f"Bias estimate (cf. paper Fig. 10): {model.name}")
    for j, ax in enumerate(axes):
        if has_truth:
            ax.plot(t, view.truth("eps", j), color="black", lw=1.4, label="truth")
        ax.plot(t, view.bias_mean(j), color="tab:gray", ls=":", lw=1.2, label="model mean c1(1-exp(-t/T))+c2")
        for stage, color, lab, ls in (("smooth", "tab:red", "smoother", "-"), ("filt", "tab:blue", "filter", "--")):
            _band(ax, t, *view.band(stage, j, 3), color, f"{lab} +-1 sigma", ls)
        ax.set_title(f"axis {names[j]}")
        ax.set_xlabel(_TIME_LABEL)
        ax.set_ylabel("bias eps [m/s^2]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    paths.append(_save(plt, fig, folder / "fig10_bias.png"))

    fig, axes = _axis_columns(plt, len(names), f"Position, filter (cf. paper Fig. 11): {model.name}")
    for j, ax in enumerate(axes):
        if has_truth:
            ax.plot(t, view.truth("r", j), color="black", lw=1.4, label="truth")
        dr = ax.plot(t, view.dead_reckoning(j, 0), color="tab:gray", ls="--", lw=1.0, label="double integration")[0]
        _band(ax, t, *view.band("filt", j, 0), "tab:blue", "filter +-1 sigma")
        if not has_truth:
            _clip_to_track(ax, dr, *view.band("filt", j, 0)[1:])
        _marks(ax, view, j)
        ax.set_title(f"axis {names[j]}")
        ax.set_xlabel(_TIME_LABEL)
        ax.set_ylabel("position r [m]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    paths.append(_save(plt, fig, folder / "fig11_position_filter.png"))

    fig, axes = _axis_columns(plt, len(names), f"Position, smoother (cf. paper Fig. 12): {model.name}")
    for j, ax in enumerate(axes):
        ref = view.truth("r", j) if has_truth else view.x("smooth", j, 0)
        if has_truth:
            ax.plot(t, ref, color="black", lw=1.4, label="truth")
        _band(ax, t, *view.band("filt", j, 0), "tab:blue", "filter +-1 sigma", "--")
        _band(ax, t, *view.band("smooth", j, 0), "tab:red", "smoother +-1 sigma")
        _marks(ax, view, j)
        _rest_marks(ax, view.small("zupt_candidates"), view.start)
        span = np.nanmax(ref) - np.nanmin(ref) if len(ref) else 1.0
        # the filter may run far away
        ax.set_ylim(np.nanmin(ref) - 0.5 * span - 1.0, np.nanmax(ref) + 0.5 * span + 1.0)
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
