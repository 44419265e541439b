"""Figures of the bias identification (matplotlib, Agg canvas, PNG files).

Per axis: the recording with the fitted bias curve (the paper's Figure 2),
its amplitude spectrum (Figure 3), the Allan deviation with its 95 %
interval and the fitted slopes, and the residual autocorrelation with the
cumulative periodogram. Figures are drawn on their own ``Figure`` objects
(no pyplot state), so this module can run inside any program.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from scipy import signal

from accelnav.fileio import atomic_output
from accelnav.identify.biasfit import BiasFit
from accelnav.identify.noiseid import FLICKER_FACTOR, NoiseId
from accelnav.identify.whiteness import Whiteness

MAX_POINTS = 1000  # block means drawn for a long recording


def _figure(w: float = 8.0, h: float = 4.8) -> Figure:
    fig = Figure(figsize=(w, h), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> Path:
    with atomic_output(path, flag="--plots") as fh:  # a plot appears whole or not at all
        fig.savefig(fh, format="png", dpi=110)
    return path


def _blocks(t: np.ndarray, y: np.ndarray, n_out: int = MAX_POINTS):
    """Block means and standard deviations of y for a readable plot of a long record."""
    L = max(1, len(y) // n_out)
    m = len(y) // L
    tb = t[: m * L].reshape(m, L).mean(axis=1)
    yb = y[: m * L].reshape(m, L)
    return tb, yb.mean(axis=1), yb.std(axis=1), L


def plot_fit(t, y, fit: BiasFit, path: Path, label: str) -> Path:
    """The recording (block means, +-1 sd of the samples) with the fitted bias curve."""
    fig = _figure()
    ax = fig.add_subplot()
    tr = np.asarray(t) - fit.t0
    tb, mean, sd, L = _blocks(tr, np.asarray(y))
    ax.fill_between(tb, mean - sd, mean + sd, color="0.88", lw=0, label=f"+-1 sd of the samples ({L} per point)")
    ax.plot(tb, mean, ".", ms=2, color="tab:blue", label=f"mean of {L} samples")
    exp = fit.exp
    curve = -exp.c1 * np.expm1(-tb / exp.T) + exp.c2
    style = "-" if fit.T_identified else ":"
    ax.plot(tb, curve, style, color="tab:red", lw=1.8, label=f"c1 (1 - exp(-t/T)) + c2, T = {exp.T:.4g} s")
    if not fit.T_identified:
        ax.axhline(fit.c2, color="k", lw=1.5, label=f"constant bias c2 = {fit.c2:.6g} (adopted)")
    # zoom on the drift and the fitted curve: the sample noise may be wider
    span = max(np.ptp(mean), np.ptp(curve), 1e-12)
    ax.set_ylim(min(mean.min(), curve.min()) - 0.6 * span, max(mean.max(), curve.max()) + 0.6 * span)
    ax.set_xlabel("time since the first sample [s]")
    ax.set_ylabel("acceleration [m/s^2]")
    verdict = "T identified" if fit.T_identified else "T not identified: constant bias"
    ax.set_title(f"{label}: stationary recording and bias fit ({verdict})")
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_spectrum(y, rate_hz: float, noise: NoiseId, path: Path, label: str) -> Path:
    """One-sided amplitude spectral density (Welch) with the Allan white-noise level."""
    y = np.asarray(y, dtype=np.float64)
    nper = int(min(len(y), 2 ** int(math.log2(max(len(y) // 8, 16)))))
    f, P = signal.welch(y, fs=rate_hz, nperseg=nper, detrend="constant")
    fig = _figure()
    ax = fig.add_subplot()
    ax.loglog(f[1:], np.sqrt(P[1:]), lw=0.8, label="Welch estimate")
    d = noise.terms.density_one_sided
    ax.axhline(d, color="tab:red", ls="--", label=f"white level from Allan: sqrt(2) N = {d:.3g} m/s^2/sqrt(Hz)")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("amplitude spectral density [m/s^2/sqrt(Hz)]")
    ax.set_title(f"{label}: spectrum of the stationary recording")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def plot_allan(noise: NoiseId, path: Path, label: str) -> Path:
    """Overlapping Allan deviation, 95 % interval, and the N, B, K lines."""
    c, k = noise.curve, noise.terms
    fig = _figure()
    ax = fig.add_subplot()
    ax.fill_between(c.tau, c.lo, c.hi, color="tab:blue", alpha=0.2, lw=0, label="95 % interval")
    ax.loglog(c.tau, c.adev, "o-", ms=3, color="tab:blue", label="overlapping Allan deviation")
    tau = c.tau
    ax.loglog(tau, k.N / np.sqrt(tau), "--", color="tab:green", label=f"white: N/sqrt(tau), N = {k.N:.3g}")
    ax.axhline(FLICKER_FACTOR * k.B, ls=":", color="tab:orange", label=f"bias instability: 0.664 B, B = {k.B:.3g}")
    kind = "bound" if k.K_is_bound else "fit"
    ax.loglog(tau, k.K * np.sqrt(tau / 3), "-.", color="tab:red", label=f"random walk ({kind}): K = {k.K:.3g}")
    ax.plot([k.tau_min], [k.adev_min], "k*", ms=10, label=f"minimum {k.adev_min:.3g} at {k.tau_min:.3g} s")
    lo = c.lo[np.isfinite(c.lo)].min() / 3
    hi = c.hi[np.isfinite(c.hi)].max() * 3
    ax.set_ylim(lo, hi)
    ax.set_xlabel("averaging time tau [s]")
    ax.set_ylabel("Allan deviation [m/s^2]")
    ax.set_title(f"{label}: Allan deviation of the fit residual")
    ax.legend(fontsize=8, loc="best")
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def plot_composite(noise: NoiseId, comp, check, path: Path, label: str) -> Path:
    """Allan deviation with the composite model, its parts, the filter's implied curve and the band checked."""
    from accelnav.identify.noisecomp import filter_avar

    c = noise.curve
    fig = _figure(8.0, 5.4)
    ax = fig.add_subplot()
    ax.fill_between(c.tau, c.lo, c.hi, color="tab:blue", alpha=0.2, lw=0, label="95 % interval")
    ax.loglog(c.tau, c.adev, "o", ms=3, color="tab:blue", label="overlapping Allan deviation")
    tau = np.geomspace(c.tau[0], c.tau[-1], 300)
    ax.loglog(tau, np.sqrt(comp.avar(tau)), "-", color="k", lw=1.8, label="composite model")
    styles = {"white": "tab:green", "flicker": "tab:orange", "random walk": "tab:red", "drift": "tab:brown"}
    for name, part in comp.avar(tau, parts=True).items():
        if not np.any(part > 0):
            continue
        text = name
        if name.startswith("GM"):
            g = comp.gm[int(name[2:]) - 1]
            text = f"{name}: sigma {g.sigma:.3g}, T {g.T:.3g} s"
        ax.loglog(tau, np.sqrt(part), "--", lw=1, color=styles.get(name, "tab:purple"), label=text)
    for R, style, what in ((check.R_white, ":", "white R"), (check.R_chosen, "-.", "written R")):
        f = filter_avar(tau, R, check.Ts_filter, check.sigma_eps, check.T_bias)
        ax.loglog(tau, np.sqrt(f), style, color="tab:gray", lw=1.5, label=f"filter's model, {what} = {R:.3g}")
        if check.R_chosen == check.R_white:
            break
    ax.axvspan(
        *check.band, color="tab:olive", alpha=0.08, label=f"band checked {check.band[0]:.3g}..{check.band[1]:.3g} s"
    )
    lo = c.lo[np.isfinite(c.lo)].min() / 3
    hi = c.hi[np.isfinite(c.hi)].max() * 3
    ax.set_ylim(lo, hi)
    ax.set_xlabel("averaging time tau [s]")
    ax.set_ylabel("Allan deviation [m/s^2]")
    ax.set_title(
        f"{label}: composite noise model; filter understates the band by x{check.worst_ratio:.3g} "
        f"(variance, at {check.worst_tau:.3g} s)",
        fontsize=9,
    )
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3, which="both")
    return _save(fig, path)


def plot_whiteness(w: Whiteness, rate_hz: float, path: Path, label: str) -> Path:
    """Residual autocorrelation with the +-1.96/sqrt(N) band, and the cumulative periodogram."""
    fig = _figure(8.0, 7.0)
    ax1, ax2 = fig.subplots(2, 1)
    lags = np.arange(len(w.acf))
    ax1.vlines(lags[1:], 0, w.acf[1:], color="tab:blue", lw=1)
    ax1.axhline(0, color="k", lw=0.6)
    ax1.axhspan(-w.band, w.band, color="tab:green", alpha=0.2, label="+-1.96/sqrt(N)")
    ax1.set_xlabel("lag [samples]")
    ax1.set_ylabel("autocorrelation")
    ax1.set_title(
        f"{label}: residual autocorrelation; Ljung-Box {w.ljung_box.verdict}; ACF band {w.acf_band.verdict}",
        fontsize=9,
    )
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    f = w.cp_freq * rate_hz
    step = max(1, len(f) // 20000)
    ax2.plot(f[::step], w.cp_U[::step], lw=1, label="cumulative periodogram")
    diag = w.cp_freq[::step] / w.cp_freq[-1] if len(f) else f
    ax2.plot(f[::step], diag, "k", lw=0.6, label="white noise")
    ax2.fill_between(
        f[::step],
        diag - w.cp_critical,
        diag + w.cp_critical,
        color="tab:green",
        alpha=0.2,
        lw=0,
        label="95 % Kolmogorov-Smirnov band",
    )
    ax2.set_xlabel("frequency [Hz]")
    ax2.set_ylabel("normalised cumulative periodogram")
    ax2.set_title(f"Bartlett test: {w.cumulative_periodogram.verdict}", fontsize=9)
    ax2.legend(fontsize=8)
    ax2.grid(alpha=0.3)
    return _save(fig, path)


def plot_all(
    t, y, rate_hz, fit: BiasFit, white: Whiteness, noise: NoiseId, folder: Path, label: str, composite=None
) -> list[Path]:
    """Write the four PNGs of one axis (five with ``composite`` = (model, band check)) into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    stem = "".join(ch if ch.isalnum() or ch in "-_" else "_" for ch in label)
    return [
        plot_fit(t, y, fit, folder / f"{stem}_fit.png", label),
        plot_spectrum(y, rate_hz, noise, folder / f"{stem}_spectrum.png", label),
        plot_allan(noise, folder / f"{stem}_allan.png", label),
        plot_whiteness(white, rate_hz, folder / f"{stem}_acf.png", label),
    ] + ([plot_composite(noise, *composite, folder / f"{stem}_noise_model.png", label)] if composite else [])
