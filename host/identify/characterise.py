"""The characterisation chain of a stationary recording: bias fit, whiteness, noise figures, merged model.

:func:`characterise` is what ``accelnav fit-bias`` runs (see that command's module notes for the
rules, the one that raises R included); the command only adds the report and the file.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from accelnav.data.recording import (
    MIN_DURATION_S,
    Recording,
    check_axis,
    check_rate,
    check_rec_units,
    in_accel,
    read_recording,
)
from accelnav.errors import UserError
from accelnav.identify.biasfit import BiasFit, FitError, fit_bias
from accelnav.identify.noisecomp import DEFAULT_BAND_S, BandCheck, Composite, check_band, fit_composite
from accelnav.identify.noiseid import NoiseId, identify_noise
from accelnav.identify.quantised import Quantisation, grid_step, quantisation
from accelnav.identify.whiteness import DEFAULT_LB_LAGS, Whiteness, whiteness
from accelnav.model.edit import revalidate, with_axis_bias, with_noise
from accelnav.model.load import DEFAULT_MODEL, Model, load_model, loads_model, model_name_from
from accelnav.progress import Progress, note


@dataclass(frozen=True, eq=False)
class AxisResult:
    name: str
    column: str
    unit: str
    fit: BiasFit
    white: Whiteness
    noise: NoiseId
    composite: Composite
    check: BandCheck | None = None
    quant: Quantisation | None = None  # the read-out step, where the samples have one

    @property
    def noise_hidden(self) -> bool:
        """The step hides this axis's noise: its noise figures are not the sensor's."""
        return self.quant is not None and self.quant.hidden


def analyse_axis(
    rec: Recording,
    axis: str,
    *,
    min_duration_s: float,
    full_scale: float | None,
    lags: int,
    sensor_range: tuple[float, str] | None = None,
    step: float = 0.0,
    hints: dict | None = None,
) -> AxisResult:
    """Check, fit, test and identify one axis of ``rec`` (with progress on stderr). ``step`` [m/s^2]: the
    read-out step of its samples (the model's, for raw counts); 0: the step of the grid they sit on, if any.
    ``hints``: what the model says about a finer read-out (Quantisation's sensor_noise, finer)."""
    j = rec.column(axis)
    source = "the model's read-out"
    if step <= 0:
        step, source = grid_step(rec.accel[:, j]), "the samples' own grid"
    y = check_axis(
        rec, axis, min_duration_s=min_duration_s, full_scale=full_scale, sensor_range=sensor_range, step=step
    )
    name = rec.axis_names[j]
    try:
        with Progress(f"fit {name}", total=4, unit="stages") as p:
            fit = fit_bias(rec.t, y, progress=p)
    except FitError as exc:
        raise UserError(f"{rec.source}: axis {name!r}: {exc}") from None
    quant = quantisation(y, fit.residuals, step, source) if step > 0 else None
    if quant is not None:
        quant = dataclasses.replace(quant, **(hints or {}))
        if quant.hidden:  # again, with the step's bound on the mean in its intervals and its decision on T
            with Progress(f"fit {name} (read-out step)", total=4, unit="stages") as p:
                fit = fit_bias(rec.t, y, progress=p, level_bound=quant.bias_bound)
    with Progress(f"white {name}", total=1, unit="tests") as p:
        white = whiteness(fit.residuals, lb_lags=lags)
        p.update(1)
    with Progress(f"allan {name}", total=1, unit="taus") as p:
        noise = identify_noise(fit.residuals, rec.rate_hz, progress=p)
    with Progress(f"noise model {name}", total=1, unit="fits") as p:
        try:
            comp = fit_composite(noise.curve, 1.0 / rec.rate_hz)
        except ValueError as exc:
            raise UserError(f"{rec.source}: axis {name!r}: composite noise model: {exc}") from None
        p.update(1)
    return AxisResult(name, rec.columns[j], rec.units[j], fit, white, noise, comp, quant=quant)


def read_stationary(
    source: str | Path,
    *,
    axes: list[str] | None = None,
    unit: str | None = None,
    rate_hz: float | None = None,
    time_column: str | None = None,
    time_unit: str | None = None,
    model: Model | None = None,
) -> Recording:
    """The recording: a CSV, gzip CSV or NPZ through the checked reader (the columns matched to ``model``'s
    axes by name, a column that names no unit in its unit), or a recorder log read directly."""
    from accelnav.link.logfile import is_log

    path = Path(source)
    if is_log(path):  # else read_recording says what is wrong with the path, if anything
        from accelnav.data.logs import log_run_arrays
        from accelnav.data.recording import from_arrays

        given = {"unit": unit, "rate": rate_hz, "time_column": time_column, "time_unit": time_unit}
        for flag, value in given.items():
            if value is not None:
                raise UserError(f"--{flag.replace('_', '-')}: not for a recorder log, which says its own")
        arrays, _ = log_run_arrays(path)
        return from_arrays(str(path), arrays, axes)
    from accelnav.data.inputs import _unit

    rec = read_recording(
        path, axes=axes, unit=unit, rate_hz=rate_hz, time_column=time_column, time_unit=time_unit,
        default_unit=_unit(model), model_axes=None if model is None else [a.name for a in model.axes],
        level=False,  # a phone or IMU log's accelerometer in its own axes: levelling would hide each axis' bias
    )  # fmt: skip
    for text in rec.notes:
        note(text)
    return rec


def as_model_axes(rec: Recording, model: Model) -> Recording:
    """``rec`` with its axes named as ``model``'s when none of its names is one and the counts agree (columns
    A0, A1 for a model of x, y), as filter and smooth take them; said in a note."""
    names = [a.name for a in model.axes]
    if set(rec.axis_names) & set(names) or len(rec.axis_names) != len(names):
        return rec
    note(f"{rec.source}: columns {', '.join(rec.columns)} -> model axes {', '.join(names)}")
    return dataclasses.replace(rec, axis_names=tuple(names))


def base_model(path: Path | None, rec: Recording) -> tuple[Model, str, bool]:
    """(model, how to name it, whether it describes this sensor)."""
    if path is not None:
        return load_model(path), str(path), True
    if rec.model_toml is not None:
        return (
            loads_model(rec.model_toml, source=f"{rec.source}:model_toml"),
            f"the model embedded in {rec.source}",
            True,
        )
    return load_model(DEFAULT_MODEL), f"the embedded default {DEFAULT_MODEL.name}", False


def read_out_steps(model: Model, rec: Recording) -> dict[str, float]:
    """The read-out step [m/s^2] of each axis of ``rec``, by the model axis its counts were converted with
    (the axis of its name, else of its place, as :func:`accelnav.data.recording.in_accel` maps them)."""
    from accelnav.model.design import steps_and_noise

    steps, _ = steps_and_noise(model)
    names = [a.name for a in model.axes]
    return {n: float(steps[names.index(n) if n in names else j]) for j, n in enumerate(rec.axis_names)}


def finer_read_out(model: Model) -> dict:
    """What the model says of a finer read-out for the advice when a step hides the noise: the datasheet's
    noise sd, and for an analog part on a reference above its supply, the step of a reference at the supply."""
    from accelnav.model.design import steps_and_noise

    _, noise = steps_and_noise(model)
    hints: dict = {"sensor_noise": noise if noise > 0 else None}
    a = model.sensor.analog
    if a is not None and a.adc_ref_v > a.supply_v:
        step = a.supply_v / 2**a.adc_bits / a.sensitivity_v_per_g * 1e3  # mg
        hints["finer"] = f"a {a.supply_v:g} V reference (the supply: ratiometric; step {step:.3g} mg)"
    return hints


def _sig(x: float, digits: int = 6) -> float:
    return float(f"{x:.{digits}g}")


def merge(
    base: Model, rec: Recording, results: list[AxisResult], *, sigma_n: str, keep_rate: bool, described: bool = True
) -> Model:
    """The base model with the fitted axes and noise figures merged in (see the module notes). ``described``:
    the base model describes this sensor (its R may stand where the read-out step hides the noise)."""
    model = base
    if not keep_rate:
        model = dataclasses.replace(model, rate_hz=_sig(rec.rate_hz, 9))
        stem = Path(rec.source).name.split(".")[0]
        model = dataclasses.replace(
            model,
            name=model_name_from(f"{stem}_fit"),  # a file name may hold what the name rule refuses
            description=f"bias and noise fitted from {Path(rec.source).name} by accelnav fit-bias; "
            f"sensor, ranges and filter from {base.name}",
        )
    names = [a.name for a in model.axes]
    for r in results:
        f = r.fit
        if f.T_identified:
            c1, c2, T = f.c1, f.c2, f.T
        else:
            T = model.axis(r.name).T if r.name in names else float(round(rec.duration))
            c1, c2 = 0.0, f.c2
        if not r.name.isidentifier():
            raise UserError(f"axis name {r.name!r} cannot name a model axis (it must be a C identifier); use --axis")
        model = with_axis_bias(model, r.name, _sig(c1), _sig(c2), _sig(T))
    Ts = model.Ts
    seen = [r for r in results if not r.noise_hidden]  # an axis whose noise the step hides gives no figure
    values = {}
    if seen:
        values = {"R": _sig(max(r.noise.R(Ts) for r in seen)), "sigma_eps": _sig(max(r.noise.sigma_eps for r in seen))}
        if sigma_n == "paper":
            values["sigma_n"] = _sig(max(r.noise.sigma_n_paper for r in seen))
    hidden = [r.quant for r in results if r.noise_hidden]
    if hidden:  # R covers at least the step's rounding; with no model of the sensor, the most noise the codes allow
        floor = max(q.step**2 / 12 + (0.0 if described else q.noise_ci[1] ** 2) for q in hidden)
        R = max(values.get("R", 0.0), model.noise.R if described else 0.0, floor)
        values["R"] = _sig(R)
    model = with_noise(model, **values) if values else model
    if len(model.axes) > 3:
        raise UserError(
            f"the model would have {len(model.axes)} axes ({', '.join(a.name for a in model.axes)}); "
            "accepted: 1 to 3; choose axes with --axis"
        )
    return revalidate(model)


def check_noise_band(model: Model, rec: Recording, results: list[AxisResult], band: tuple[float, float]):
    """Check each axis's composite noise against the merged model's noise over ``band``; raise R where needed."""
    out = []
    for r in results:
        if r.noise_hidden:  # no noise figure to check
            out.append(r)
            continue
        try:
            chk = check_band(
                r.noise.curve,
                r.composite,
                R=model.noise.R,
                Ts_filter=model.Ts,
                sigma_eps=model.noise.sigma_eps,
                T_bias=model.axis(r.name).T,
                band=band,
            )
        except ValueError as exc:
            raise UserError(f"{rec.source}: axis {r.name!r}: --noise-band: {exc}") from None
        out.append(dataclasses.replace(r, check=chk))
    R = max((r.check.R_chosen for r in out if r.check is not None), default=0.0)
    if R > model.noise.R:
        model = revalidate(with_noise(model, R=_sig(R)))
    return out, model


@dataclass(frozen=True, eq=False)
class Characterisation:
    """What :func:`characterise` found: the merged model, and per axis the fit, whiteness and noise."""

    model: Model  # the base model with the fitted bias and noise figures merged in
    base: Model
    base_label: str  # how the base model is named in reports
    recording: Recording
    axes: list[AxisResult]

    def to_dataframe(self):
        """One row per axis: the bias constants, the noise terms and the band check, in SI units."""
        from accelnav.data.run import pandas_or_error

        pd = pandas_or_error()
        rows = []
        for r in self.axes:
            f, k = r.fit, r.noise.terms
            if r.noise_hidden:  # the step hides the noise: no figure from it
                k = dataclasses.replace(k, N=float("nan"), B=float("nan"), K=float("nan"))
            rows.append(
                {
                    "axis": r.name,
                    "column": r.column,
                    "T_identified": f.T_identified,
                    "c1": f.c1 if f.T_identified else 0.0,
                    "c2": f.c2,
                    "T": f.T if f.T_identified else float("nan"),
                    "white": r.white.white,
                    "N": k.N,
                    "B": k.B,
                    "K": k.K,
                    "K_is_bound": k.K_is_bound,
                    "R_white": r.check.R_white if r.check is not None else float("nan"),
                    "R_chosen": r.check.R_chosen if r.check is not None else float("nan"),
                }
            )
        return pd.DataFrame(rows).set_index("axis")


def characterise(
    source: str | Path,
    model: Model | str | Path | None = None,
    *,
    axes: list[str] | None = None,
    unit: str | None = None,
    rate_hz: float | None = None,
    time_column: str | None = None,
    time_unit: str | None = None,
    min_duration_s: float = MIN_DURATION_S,
    sigma_n: str = "keep",
    noise_band: tuple[float, float] = DEFAULT_BAND_S,
    lags: int = DEFAULT_LB_LAGS,
) -> Characterisation:
    """Bias fit, whiteness and noise figures of a stationary recording, merged into a model.

    ``model``: the model to merge into (a Model or a file); None: the one embedded in the recording,
    else the embedded default (whose rate then becomes the recording's). ``sigma_n``: "keep" the base
    model's, or "paper" for the derivative-variance rule. Refusals raise UserError in one line.
    """
    if lags < 1:
        raise UserError(f"--lags: got {lags}; accepted: a positive number of lags")
    lo, hi = noise_band
    if not (0 < lo < hi):
        raise UserError(f"--noise-band: got {lo:g} {hi:g}; accepted: two times in s, 0 < LO < HI")
    if sigma_n not in ("keep", "paper"):
        raise UserError(f"--sigma-n: got {sigma_n!r}; accepted: keep, paper")
    if model is not None and not isinstance(model, Model):
        model = load_model(Path(model))
    opts = dict(axes=axes, unit=unit, rate_hz=rate_hz, time_column=time_column, time_unit=time_unit)
    rec = read_stationary(source, **opts, model=model)
    if isinstance(model, Model):
        base, base_label, given = model, str(model.source), True
    else:
        base, base_label, given = base_model(None, rec)
    rec = as_model_axes(rec, base)  # columns A0, A1 fit the model's x, y (the default's too), as smooth reads them
    counts = "counts" in rec.units
    if counts:  # the model's own conversion, as the firmware's; without --model the default's, as
        rec = in_accel(rec, base)  # filter and smooth read counts, said in a note
        note(rec.notes[-1])
    full_scale = base.max_accel_m_s2 if given else None
    check_rec_units(rec, full_scale, base_label)  # a unit no name said, against what the data say
    if given:  # the model keeps its rate: the recording must have it (the check filter and smooth make)
        check_rate(rec, base.rate_hz, base_label)
    note(
        f"{rec.source}: {rec.n} samples at {rec.rate_hz:.6g} Hz ({rec.duration:.6g} s), "
        f"axes {', '.join(rec.axis_names)}"
    )
    sensor_range = (base.max_accel_m_s2, f"the sensor of {base_label}")  # the range the written model claims
    steps = read_out_steps(base, rec) if counts else {}
    hints = finer_read_out(base) if given else {}
    results = [
        analyse_axis(
            rec,
            a,
            min_duration_s=min_duration_s,
            full_scale=full_scale,
            lags=lags,
            sensor_range=sensor_range,
            step=steps.get(a, 0.0),
            hints=hints,
        )
        for a in rec.axis_names
    ]
    merged = merge(base, rec, results, sigma_n=sigma_n, keep_rate=given, described=given)
    results, merged = check_noise_band(merged, rec, results, (float(lo), float(hi)))
    return Characterisation(merged, base, base_label, rec, results)
