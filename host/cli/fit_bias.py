"""``accelnav fit-bias``: bias model, whiteness and noise figures from a stationary recording.

For each axis: read and check the samples (:mod:`accelnav.data.recording`), fit
eps(t) = c1 (1 - exp(-t/T)) + c2 (:mod:`accelnav.identify.biasfit`), test the residuals
for whiteness (:mod:`accelnav.identify.whiteness`), identify the noise from their Allan
deviation (:mod:`accelnav.identify.noiseid`), print a report and optionally draw the
figures (:mod:`accelnav.plots.biasfit`). Then write a model file: the input
model (``--model``; else the one embedded in the recording; else the embedded
default) with the fitted axes merged in and the noise figures replaced:

* each fitted axis gets c1, c2, T; when T is not identified the axis gets
  c1 = 0, c2 = mean and keeps the base model's T (with c1 = 0 T only sets how
  fast the filter's bias state reverts to c2), or the record length for a new axis;
* R = max over the fitted axes of N^2 / Ts (Ts of the output model), unless the
  composite noise model (:mod:`accelnav.identify.noisecomp`) shows that this
  white-noise R understates the noise over the band that matters for the
  filter (``--noise-band``, default 0.1 .. 100 s) by more than 1.5x in
  variance (measured on the Allan curve itself where the composite fits the
  band poorly): then R is the band's R (the smallest
  white R whose Allan curve, with the model's bias, covers the noise over the
  band), and the model's header comments say so with the numbers;
  sigma_eps = max over the fitted axes of K (fitted or bound);
* sigma_n is kept from the base model (a stationary recording cannot identify
  it) unless ``--sigma-n paper`` asks for the paper's rule;
* samples read through a step (raw counts: the model's read-out; else a grid the
  samples sit on) whose noise is under a quarter step
  (:mod:`accelnav.identify.quantised`) give no noise figure: the report says so
  in one line with the fixes, such axes are left out of R and sigma_eps (R is at
  least the base model's and the step's rounding q^2/12, or with no model of the
  sensor q^2/12 plus the most noise the codes allow); wherever the rounding's
  bound on the mean matters, the bias intervals carry it.
  A pile of samples at the data's own extreme is then no sign of clipping: only
  the rails decide.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from accelnav.cli.args import clock_args, reader_options
from accelnav.data.recording import MIN_DURATION_S, Recording
from accelnav.fileio import check_output
from accelnav.identify.characterise import AxisResult, characterise
from accelnav.identify.noisecomp import DEFAULT_BAND_S, WARN_RATIO
from accelnav.identify.quantised import advice
from accelnav.identify.whiteness import DEFAULT_LB_LAGS
from accelnav.model.edit import save_model
from accelnav.model.load import DEFAULT_MODEL, G0, Model
from accelnav.progress import Progress


def register(sub) -> None:
    p = sub.add_parser(
        "fit-bias",
        help="identify the bias model and noise figures from a stationary recording",
        description="Fit eps(t) = c1 (1 - exp(-t/T)) + c2 to a stationary recording, test the residuals for "
        "whiteness, identify the noise from the Allan deviation, and write a model file.",
    )
    p.add_argument(
        "recording", type=Path, help="CSV (plain or gzip), NPZ (as written by accelnav sim) or a recorder log (.acnlog)"
    )
    p.add_argument(
        "--axis",
        action="append",
        metavar="NAME",
        help="axis to fit: a column name or its short name (acc_x_g or x); repeat for several; default: all",
    )
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        metavar="IN.toml",
        help="model file to merge the results into; default: the model embedded in the recording, "
        f"else the embedded {DEFAULT_MODEL.name}",
    )
    p.add_argument("--out", type=Path, required=True, metavar="OUT.toml", help="model file to write (TOML)")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write the figures (PNG) into DIR")
    p.add_argument(
        "--unit", default=None, help="unit of the acceleration columns: g, mg or m/s^2; default: from the name"
    )
    clock_args(p)
    p.add_argument("--time-column", default=None, metavar="NAME", help="time column; default: t, t_s, time, ...")
    p.add_argument(
        "--min-duration",
        type=float,
        default=MIN_DURATION_S,
        metavar="S",
        help=f"refuse recordings shorter than this; default: {MIN_DURATION_S:g} s",
    )
    p.add_argument(
        "--sigma-n",
        choices=("keep", "paper"),
        default="keep",
        help="sigma_n: keep the base model's (default) or use the paper's derivative-variance rule",
    )
    p.add_argument(
        "--noise-band",
        type=float,
        nargs=2,
        default=DEFAULT_BAND_S,
        metavar=("LO", "HI"),
        help="averaging times [s] over which the filter's noise model is checked against the composite "
        f"noise model (the times between aids that drive position error); default: {DEFAULT_BAND_S[0]:g} "
        f"{DEFAULT_BAND_S[1]:g}",
    )
    p.add_argument("--lags", type=int, default=DEFAULT_LB_LAGS, help=f"Ljung-Box lags; default: {DEFAULT_LB_LAGS}")
    p.set_defaults(func=cmd_fit_bias)


def cmd_fit_bias(args: argparse.Namespace) -> int:
    _fit_bias_run(args)
    return 0


def _fit_bias_run(args: argparse.Namespace):
    """The command's work and lines; returns the Characterisation (the demo compares it with the truth)."""
    check_output(args.out)  # a directory named as the model to write is refused before the work
    ch = characterise(
        args.recording,
        args.model,
        **reader_options(args),
        min_duration_s=args.min_duration,
        sigma_n=args.sigma_n,
        noise_band=tuple(args.noise_band),
        lags=args.lags,
    )
    model, rec, results = ch.model, ch.recording, ch.axes
    for r in results:
        print()
        print("\n".join(axis_report(r)))
    save_model(args.out, model, header=provenance(rec, results, ch.base_label))  # whole or not at all
    print()
    print("\n".join(model_report(model, ch.base, ch.base_label, rec, results, args.sigma_n, args.out)))

    if args.plots is not None:
        from accelnav.plots.biasfit import plot_all

        paths = []
        with Progress("plots", total=len(results), unit="axes") as p:
            for i, r in enumerate(results):
                y = rec.axis(r.name)
                paths += plot_all(
                    rec.t,
                    y,
                    rec.rate_hz,
                    r.fit,
                    r.white,
                    r.noise,
                    args.plots,
                    r.name,
                    (r.composite, r.check) if r.check is not None else None,
                )
                p.update(i + 1)
        print(f"figures: {', '.join(str(p) for p in paths)}")
    return ch


def composite_table(r: AxisResult) -> list[str]:
    """The composite noise model of one axis as a markdown table (also printed by the report)."""
    c, g0 = r.composite, G0 / 1e3
    rows = [
        "| term | value | unit | in mg units |",
        "|---|---|---|---|",
        f"| white N | {c.N:.4g} | m/s^2/sqrt(Hz) | {c.N / g0:.4g} mg/sqrt(Hz) |",
        f"| random walk K | {c.K:.4g} | m/s^2/sqrt(s) | {c.K / g0:.4g} mg/sqrt(s) |",
    ]
    if c.B > 0:
        rows.append(f"| bias instability B | {c.B:.4g} | m/s^2 | {c.B / g0:.4g} mg |")
    if c.D > 0:
        rows.append(f"| drift D | {c.D:.4g} | m/s^3 | {c.D / g0:.4g} mg/s |")
    for i, g in enumerate(c.gm):
        rows.append(
            f"| Gauss-Markov {i + 1}: sigma, T | {g.sigma:.4g}, {g.T:.4g} | m/s^2, s | {g.sigma / g0:.4g} mg, "
            f"white-equivalent {g.N_equiv / g0:.4g} mg/sqrt(Hz) |"
        )
    rows.append(
        f"| fit quality | chi2/point {c.chi2 / c.n_points:.3g}, {100 * c.outside_share:.0f} % of {c.n_points} "
        f"points outside 95 %, worst deviation {100 * c.max_rel_err:.0f} % "
        f"| tau {c.tau_range[0]:.3g}..{c.tau_range[1]:.4g} s | |"
    )
    return rows


def band_report(r: AxisResult) -> list[str]:
    k = r.check
    lines = [
        f"    filter's noise model (R = {k.R_white:.4g}, sigma_eps = {k.sigma_eps:.3g}, T = {k.T_bias:.4g} s) against "
        f"the {k.reference} Allan variance over the band {k.band[0]:.3g} .. {k.band[1]:.4g} s: worst ratio "
        f"x{k.worst_ratio:.3g} in variance at tau = {k.worst_tau:.3g} s"
    ]
    if k.reference == "empirical":
        lines.append(
            f"    WARNING: the composite model fits this band poorly ({100 * k.band_outside_share:.0f} % of its points "
            f"outside their 95 % interval): the check above uses the Allan curve itself (points with >= 10 degrees of "
            "freedom)"
        )
    if k.understated:
        lines.append(
            f"    WARNING: the white-noise R understates the noise in this band by x{k.worst_ratio:.3g} in variance "
            f"(threshold x{WARN_RATIO:g}): the noise is not white there (band-limited / Gauss-Markov), and position "
            f"error, driven by this band, would be underestimated. The band's R = {k.R_band:.4g} "
            f"(x{k.R_band / k.R_white:.3g}) covers it."
        )
        if k.R_band > 1.2 * k.worst_ratio * k.R_white:
            lines.append(
                f"    (more than the worst ratio x{k.worst_ratio:.3g}: where the filter's bias walk sigma_eps carries "
                "part of its curve, a white R must make up the rest alone)"
            )
    else:
        lines.append(f"    the white-noise R represents this band (ratio at most x{WARN_RATIO:g})")
    return lines


# --------------------------------------------------------------------------
# Report


def _fmt_mg(x: float) -> str:
    return f"{x / G0 * 1e3:.3g} mg"


def _fmt_ci(ci: tuple[float, float], fmt: str = ".6g") -> str:
    return f"[{ci[0]:{fmt}}, {ci[1]:{fmt}}]"


def axis_report(r: AxisResult) -> list[str]:
    f, w, nz = r.fit, r.white, r.noise
    e = f.exp
    out = [f"axis {r.name} (column {r.column}, in {r.unit}): {f.n} samples"]
    out.append(f"  bias fit: {f.verdict}")
    if f.T_identified:
        out.append(f"    c1 = {f.c1:.6g} m/s^2  se {f.se[0]:.3g}  95 % {_fmt_ci(f.ci95[0])}  ({_fmt_mg(f.c1)})")
        out.append(f"    c2 = {f.c2:.6g} m/s^2  se {f.se[1]:.3g}  95 % {_fmt_ci(f.ci95[1])}  ({_fmt_mg(f.c2)})")
        out.append(f"    T  = {f.T:.6g} s  se {f.se[2]:.3g}  95 % profile {_fmt_ci(f.ci95[2], '.4g')}")
    else:
        out.append(
            f"    constant bias c2 = {f.c2:.6g} m/s^2  se {f.se[1]:.3g}  95 % {_fmt_ci(f.ci95[1])}  ({_fmt_mg(f.c2)})"
        )
        out.append(
            f"    (rejected exponential: c1 = {e.c1:.4g} m/s^2, c2 = {e.c2:.6g} m/s^2, T = {e.T:.4g} s, "
            f"T profile 95 % {_fmt_ci(e.ci95[2], '.4g')}{'' if all(e.T_ci_closed) else ' open'})"
        )
    q = r.quant
    if q is not None and q.hidden:  # characterise refitted with the bound
        out.append(
            f"    the intervals include +-{q.bias_bound:.4g} m/s^2 on c2 (twice that on c1): with a noise of "
            f"{q.noise_sd / q.step:.2g} read-out step ({q.step:.4g} m/s^2), the mean of the readings may sit that far "
            "from the signal's"
        )
    elif q is not None and q.bias_bound > 1e-3 * q.step:
        out.append(
            f"    not in the intervals: the rounding may move a level by up to {q.bias_bound:.3g} m/s^2 (the noise, "
            f"{q.noise_sd / q.step:.2g} read-out step of {q.step:.4g} m/s^2, dithers it; the figure is its worst case)"
        )
    out.append(
        f"    residual rms {f.sigma:.4g} m/s^2 ({_fmt_mg(f.sigma)}); variance factors for residual correlation: "
        f"short-range srf = {f.srf:.3g}, long-run vif = {f.vif:.3g} (both 1 for white residuals)"
    )
    out.append(f"  whiteness of the residuals ({w.n} samples):")
    for t in w.tests:
        out.append(f"    {t.line()}")
    if not w.white:
        out.append(
            "    -> the residuals are not white: the intervals above allow only for short-range correlation "
            f"and are too narrow; widened by the long-run variance (vif = {f.vif:.3g}) they are:"
        )
        lr = f.ci95_lr
        if f.T_identified:
            out.append(f"       c1 {_fmt_ci(lr[0])}, c2 {_fmt_ci(lr[1])} m/s^2, T {_fmt_ci(lr[2], '.4g')} s")
        else:
            out.append(f"       c2 {_fmt_ci(lr[1])} m/s^2")
    if r.noise_hidden:
        out.append(f"  noise: {advice(q)}")
        return out
    k = nz.terms
    c = nz.curve
    out.append(f"  noise (overlapping Allan deviation of the residual, tau {c.tau[0]:.3g} .. {c.tau[-1]:.4g} s):")
    out.append(
        f"    white noise N = {k.N:.4g} m/s^2/sqrt(Hz) at tau = 1 s; one-sided density sqrt(2) N = "
        f"{k.density_one_sided:.4g} m/s^2/sqrt(Hz) ({_fmt_mg(k.density_one_sided)}/sqrt(Hz))"
    )
    out.append(
        f"    Allan minimum {k.adev_min:.4g} m/s^2 ({_fmt_mg(k.adev_min)}) at tau = {k.tau_min:.4g} s, "
        f"95 % {_fmt_ci(k.adev_min_ci, '.3g')}; bias instability B = min/0.664 = {k.B:.4g} m/s^2 ({_fmt_mg(k.B)})"
    )
    if k.K_is_bound:
        out.append(
            f"    random walk: not seen at the longest tau; upper bound K <= {k.K_bound:.4g} m/s^2/sqrt(s) "
            f"(fitted term {k.K_fit:.3g})"
        )
    else:
        out.append(f"    random walk K = {k.K:.4g} m/s^2/sqrt(s) (bound {k.K_bound:.4g})")
    out.append(
        f"    fitted flicker B = {k.B_fit:.4g} m/s^2, drift D = {k.D:.4g} m/s^3 "
        f"(N, B, K, D fitted over tau {k.fit_tau_range[0]:.3g} .. {k.fit_tau_range[1]:.4g} s)"
    )
    out.append(
        f"    sample variance {nz.sample_var:.4g} (m/s^2)^2 (white-equivalent N^2/Ts = {nz.R():.4g}); "
        f"paper's rule var(dy/dt) = {nz.deriv_var:.4g} (m/s^3)^2 -> sigma_n = sqrt(var * Ts) = {nz.sigma_n_paper:.4g}"
    )
    out.append("  composite noise model (white + random walk + Gauss-Markov terms, flicker and drift where seen):")
    out += [f"    {row}" for row in composite_table(r)]
    if r.composite.fit_poor:
        out.append(
            f"    WARNING: poor fit: {100 * r.composite.outside_share:.0f} % of the points lie outside their 95 % "
            "interval; the composite's terms are only indicative"
        )
    if r.check is not None:
        out += band_report(r)
    return out


def model_report(
    model: Model, base: Model, base_label: str, rec: Recording, results, sigma_n: str, out: Path
) -> list[str]:
    lines = [f"model written to {out} (merged into {base_label}):"]
    for r in results:
        ax = model.axis(r.name)
        how = "fitted" if r.fit.T_identified else "constant bias; T kept, it has no effect on the mean with c1 = 0"
        lines.append(f"  axis {ax.name}: c1 = {ax.c1:.6g}, c2 = {ax.c2:.6g} m/s^2, T = {ax.T:.6g} s ({how})")
    seen = [r for r in results if not r.noise_hidden]
    names = ", ".join(r.name for r in seen)
    hidden = ", ".join(r.name for r in results if r.noise_hidden)
    n = model.noise
    raised = [r for r in results if r.check is not None and r.check.R_chosen > r.check.R_white]
    if not seen:
        lines.append(
            f"  R = {n.R:.6g} (m/s^2)^2: {format_hidden_R(n.R, base, results)}; "
            f"sigma_eps = {n.sigma_eps:.6g} m/s^2/sqrt(s) "
            f"kept from the base model: the read-out step hides the noise on every axis ({hidden}), so the recording "
            "gives no noise figure"
        )
    elif raised:
        lines.append(
            f"  R = {n.R:.6g} (m/s^2)^2: the band's R, chosen because the white-noise R "
            f"({raised[0].check.R_white:.4g}) misrepresents the noise over "
            f"{raised[0].check.band[0]:.3g} .. {raised[0].check.band[1]:.4g} s on axis "
            + ", ".join(f"{r.name} (x{r.check.worst_ratio:.3g})" for r in raised)
        )
    else:
        lines.append(f"  R = {n.R:.6g} (m/s^2)^2 = max over {names} of N^2/Ts at Ts = {model.Ts:.6g} s")
    if seen:
        bound = any(r.noise.terms.K_is_bound for r in seen)
        lines.append(
            f"  sigma_eps = {n.sigma_eps:.6g} m/s^2/sqrt(s) = max over {names} of K"
            + (" (an upper bound where no random walk is seen)" if bound else "")
        )
    if seen and hidden:
        lines.append(
            f"  (axes {hidden}: the read-out step hides their noise, so they give no figure to R and sigma_eps; "
            f"R is at least {format_hidden_R(None, base, results)})"
        )
    paper = max((r.noise.sigma_n_paper for r in seen), default=float("nan"))
    if sigma_n == "paper":
        lines.append(f"  sigma_n = {n.sigma_n:.6g} from the paper's rule (the base model had {base.noise.sigma_n:.6g})")
    else:
        lines.append(
            f"  sigma_n = {n.sigma_n:.6g} kept from the base model: it describes motion, which a stationary "
            f"recording cannot identify (the paper's rule would give {paper:.4g}; --sigma-n paper)"
        )
    if abs(model.rate_hz / rec.rate_hz - 1) > 1e-6:
        lines.append(
            f"  note: the model runs at {model.rate_hz:g} Hz, the recording at {rec.rate_hz:.6g} Hz; "
            "R is mapped to the model's rate"
        )
    return lines


def format_hidden_R(R: float | None, base: Model, results) -> str:
    """Where R comes from for axes whose noise the read-out step hides (see characterise.merge)."""
    hidden = [r.quant for r in results if r.noise_hidden]
    q = max(x.step for x in hidden)
    if R is not None and R == base.noise.R:
        return "kept from the base model"
    if R is not None and R > q**2 / 12 * (1 + 1e-5):
        return (
            "the step's rounding q^2/12 plus the most noise the codes' shares allow (their 95 % upper end): "
            "no model of this sensor given"
        )
    if R is not None:
        return f"the step's rounding q^2/12 at q = {q:.4g} m/s^2 (the base model's R is less)"
    return f"the base model's R {base.noise.R:.4g} and the step's rounding q^2/12 = {q**2 / 12:.4g}"


def provenance(rec: Recording, results, base_label: str) -> str:
    lines = [
        "accelnav model written by accelnav fit-bias",
        f"recording: {Path(rec.source).name}, {rec.n} samples at {rec.rate_hz:.6g} Hz ({rec.duration:.6g} s)",
        f"base: {base_label}",
    ]
    for r in results:
        f, k = r.fit, r.noise.terms
        if f.T_identified:
            lines.append(
                f"axis {r.name}: c1 = {f.c1:.4g} +- {f.se[0]:.2g}, c2 = {f.c2:.6g} +- {f.se[1]:.2g} m/s^2, "
                f"T = {f.T:.4g} s (95 % {f.ci95[2][0]:.4g} .. {f.ci95[2][1]:.4g})"
            )
        else:
            lines.append(f"axis {r.name}: T not identified, constant bias c2 = {f.c2:.6g} +- {f.se[1]:.2g} m/s^2")
        verdicts = ", ".join(f"{t.name} {'white' if t.white else 'not white'}" for t in r.white.tests)
        lines.append(f"  residuals: {verdicts}")
        if r.noise_hidden:
            q = r.quant
            lines.append(
                f"  noise hidden by the read-out step {q.step:.4g} m/s^2 ({q.noise_sd / q.step:.2g} step from the "
                f"codes): no noise figure fitted; bias intervals include +-{q.bias_bound:.4g} m/s^2"
            )
            continue
        lines.append(
            f"  Allan: N = {k.N:.4g} m/s^2/sqrt(Hz), minimum {k.adev_min:.3g} m/s^2 at {k.tau_min:.3g} s, "
            f"K {'<=' if k.K_is_bound else '='} {k.K:.3g} m/s^2/sqrt(s)"
        )
        c, chk = r.composite, r.check
        gm = "; ".join(f"GM sigma {g.sigma:.3g} m/s^2, T {g.T:.3g} s" for g in c.gm) or "no GM term"
        lines.append(
            f"  composite: N = {c.N:.4g}, K = {c.K:.3g}, B = {c.B:.3g}, D = {c.D:.3g}; {gm}; "
            f"{100 * c.outside_share:.0f} % of points outside 95 %"
        )
        if chk is not None:
            choice = (
                f"R raised to the band's R {chk.R_band:.4g}" if chk.R_chosen > chk.R_white else "white-noise R kept"
            )
            lines.append(
                f"  noise band {chk.band[0]:.3g} .. {chk.band[1]:.4g} s: the white-noise R {chk.R_white:.4g} "
                f"understates the {chk.reference} Allan variance by at most x{chk.worst_ratio:.3g} "
                f"(at {chk.worst_tau:.3g} s; threshold x{WARN_RATIO:g}): {choice}"
            )
    return "\n".join(lines)
