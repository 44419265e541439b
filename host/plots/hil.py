"""``accelnav hil --plots``: the firmware against the truth and the float64 reference."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accelnav.fileio import atomic_output
from accelnav.plots.run import pyplot


def plot_hil(run, c, path: Path, title: str) -> Path:
    """Per axis: position of the truth, the firmware's filter, the smoother with and without ZUPTs (top), and
    the firmware's distance from the float64 filter in units of its sigma (bottom). ``run``: a SimRun or a
    RecordedRun (no truth), ``c`` the :func:`accelnav.hil_sim.targets.hil.compare` result."""
    plt = pyplot()
    t = run.t
    n_axes = len(run.axis_names)
    fig, axes = plt.subplots(2, n_axes, figsize=(6.5 * n_axes, 7), sharex=True, squeeze=False)
    for j, name in enumerate(run.axis_names):
        ax = axes[0, j]
        if run.r is not None:  # a recording has no truth
            ax.plot(t, run.r[:, j], color="black", lw=1.6, label="truth")
        ax.plot(t, c.fw["r"][:, j], color="tab:blue", lw=1.2, label="firmware filter")
        ax.plot(t, c.smooth_x[j, :, 0], color="tab:red", lw=1.0, ls="--", label="smoother")
        ax.plot(t, c.zupt_x[j, :, 0], color="tab:green", lw=1.2, label="smoother + ZUPT")
        ax.set_ylabel("position r [m]")
        ax.set_title(f"axis {name}")
        ax.grid(True, alpha=0.3)
        ax = axes[1, j]
        for i, key in enumerate(("r", "u", "a", "eps")):
            sd = c.ref_sd[j, :, i]
            e = np.abs(c.fw[key][:, j] - c.ref_x[j, :, i]) / np.where(sd > 0, sd, np.inf)  # r, u known at k = 0
            ax.semilogy(t, np.maximum(e, 1e-12), lw=0.8, label=key)
        ax.set_ylabel("|firmware - float64| / sigma")
        ax.set_xlabel("time [s]")
        ax.grid(True, alpha=0.3, which="both")
    axes[0, 0].legend(fontsize=8)
    axes[1, 0].legend(fontsize=8, ncol=4)
    fig.suptitle(title)
    fig.tight_layout()
    with atomic_output(path, flag="--plots") as fh:  # a plot appears whole or not at all
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return path
