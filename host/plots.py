"""Plots a person would look at (matplotlib, Agg backend, PNG files)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from codegen.model import Model

from .pipeline import dead_reckoning


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _band(ax, t, x, sd, color, label, ls="-"):
    ax.plot(t, x, color=color, lw=1.2, ls=ls, label=label)
    ax.fill_between(t, x - sd, x + sd, color=color, alpha=0.18, lw=0)


def plot_run(arrays: dict[str, np.ndarray], model: Model, path: str | Path, title: str = "") -> Path:
    """Position, velocity and bias of every axis: truth, double integration, filter and smoother (+-1 sigma)."""
    plt = _pyplot()
    t = arrays["t"]
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
                ax.plot(t, plain[j, :, i], color="tab:gray", lw=1.0, ls="--", label="double integration")
            # the smoother underneath, the filter dashed on top: they coincide where no future data helps
            for stage, color, lab, ls in (("smooth", "tab:red", "smoother", "-"), ("filt", "tab:blue", "filter", "--")):
                if f"{stage}_x" in arrays:
                    x = arrays[f"{stage}_x"][j, :, i]
                    sd = np.sqrt(arrays[f"{stage}_P"][j, :, i, i])
                    _band(ax, t, x, sd, color, f"{lab} +-1 sigma", ls)
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
        axes[-1, j].set_xlabel("time [s]")
    axes[0, 0].legend(loc="best", fontsize=8)
    fig.suptitle(title or f"accelnav: {model.name}")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
