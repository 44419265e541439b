"""A model file for a new part, from its datasheet: what ``accelnav init`` writes.

:func:`new_model` takes the read-out (analog ratiometric ADC, duty-cycle timer capture, digital LSB per g,
or already calibrated samples), the axes and the rate, and returns a complete model that the loader has
accepted, with the noise figures a datasheet gives and placeholders for what only a measurement gives
(the bias constants: ``fit-bias``; zero-g and sensitivity per axis: ``calibrate``). :func:`header` is the
comment block that says where every number came from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .edit import dump_model
from .load import G0, Model, ModelError, loads_model

KINDS = ("analog", "duty_cycle", "digital", "calibrated")

# Datasheet-typical parts; a value given beside --part overrides its value. Sources in "note". Limits the
# part's datasheet sets, checked by new_model: supply_min_v/supply_max_v (operating supply), range_max_g
# (the full scale it measures). axis_noise_density_g_rthz: per-axis densities where the axes differ.
PRESETS: dict[str, dict] = {
    "adxl335": dict(
        kind="analog",
        part="ADXL335",
        range_g=3.6,  # +-3.6 g typical (+-3 g minimum)
        range_max_g=3.6,
        supply_min_v=1.8,
        supply_max_v=3.6,
        sensitivity_v_per_g=0.3,  # at Vs = 3 V, ratiometric: scaled by supply_v / 3
        sensitivity_at_v=3.0,
        noise_density_g_rthz=150e-6,  # X and Y; Z is 300 ug/sqrt(Hz)
        axis_noise_density_g_rthz=dict(x=150e-6, y=150e-6, z=300e-6),
        bandwidth_hz=50.0,  # set by the Cx capacitors: 0.1 uF gives 50 Hz
        axes=("x", "y", "z"),
        note="ADXL335 datasheet (Analog Devices, Rev. B): +-3.6 g typical, supply 1.8 to 3.6 V, 300 mV/g at 3 V "
        "ratiometric, zero g at Vs/2, 150 ug/sqrt(Hz) on X and Y (300 on Z), bandwidth set by Cx (0.1 uF: 50 Hz)",
    ),
    "adxl250": dict(
        kind="analog",
        part="ADXL250",
        range_g=50.0,
        range_max_g=50.0,
        supply_min_v=4.0,
        supply_max_v=6.0,
        sensitivity_v_per_g=0.038,
        sensitivity_at_v=5.0,
        noise_density_g_rthz=1e-3,
        bandwidth_hz=50.0,
        axes=("x", "y"),
        note="ADXL250 datasheet: +-50 g, supply 4 to 6 V, 38 mV/g at 5 V ratiometric, zero g at Vs/2, about 1 "
        "mg/sqrt(Hz)",
    ),
    "adxl202": dict(
        kind="duty_cycle",
        part="ADXL202",
        range_g=2.0,
        range_max_g=2.0,
        supply_min_v=3.0,
        supply_max_v=5.25,
        zero_g_duty=0.5,
        duty_per_g=0.125,
        noise_density_g_rthz=200e-6,
        bandwidth_hz=10.0,
        axes=("x", "y"),
        note="ADXL202 datasheet: +-2 g, supply 3 to 5.25 V, duty 50 % + 12.5 %/g, 200 ug/sqrt(Hz)",
    ),
}

# Placeholders for what a datasheet does not give, each replaced by a measurement (see next_steps)
SIGMA_N = 1.0  # m/s^2/sqrt(s): white jerk of a hand-held motion; `tune` fits it from a motion recording
SIGMA_EPS = 1e-3  # m/s^2/sqrt(s): bias random walk; `fit-bias` measures it
T_BIAS = 300.0  # s: warm-up time constant until `fit-bias` measures it
# The still recording fit-bias needs: four warm-up time constants, so the fit sees the warm-up settle. The
# firmware runs its filter through that recording too, so the run its fixed-point ranges are proved for is
# that long: max_run_s is this one number, and what `init` asks the user to record is read back from it.
STILL_RECORD_S = 4 * T_BIAS
RANGES = dict(max_velocity_m_s=10.0, max_position_m=1000.0, max_run_s=STILL_RECORD_S)


def preset(part: str, supply_v: float | None = None) -> dict:
    """The datasheet values of a known ``part`` (a key of PRESETS), a ratiometric sensitivity scaled to
    ``supply_v``; ModelError naming the known parts otherwise."""
    key = part.strip().lower()
    if key not in PRESETS:
        raise ModelError("init", "part", f"no preset {part!r}; known: {', '.join(PRESETS)} (or give the values)")
    v = dict(PRESETS[key])
    at = v.pop("sensitivity_at_v", None)
    if at is not None and supply_v is not None:
        v["sensitivity_v_per_g"] = float(f"{v['sensitivity_v_per_g'] * supply_v / at:.6g}")  # ratiometric: x Vs
    return v


def part_values(part: str | None, given: dict) -> dict:
    """What :func:`new_model` takes for ``part`` (a PRESETS key, or None) described by ``given`` (model keys,
    from flags or answers alike: ``accelnav init`` gathers both into ``given`` before calling this, once).

    The preset's values, overridden by ``given``; its ratiometric sensitivity scaled to the supply in ``given``
    (the supply the part runs at, however it was given) unless ``given`` holds a sensitivity, which is taken
    as measured at that supply. A noise density in ``given`` replaces the preset's per-axis ones."""
    given = {k: x for k, x in given.items() if x is not None}
    values = preset(part, given.get("supply_v")) if part else {}
    if "noise_density_g_rthz" in given:
        values.pop("axis_noise_density_g_rthz", None)
    values.update(given)
    return values


def _check_limits(v: dict) -> None:
    """Refuse a supply or a range outside what the part's datasheet allows (the PRESETS' limits)."""
    part = v.get("part") or "part"
    lo, hi = v.get("supply_min_v"), v.get("supply_max_v")
    supply = v.get("supply_v")
    if supply is not None and lo is not None and hi is not None and not lo <= supply <= hi:
        hint = ""
        if supply > hi and hi < 5.0 <= supply:
            hint = "; on a 5 V board power it from the 3.3 V pin: --supply 3.3 --adc-ref 5 (the ADC's own reference)"
        said = f"got {supply:g} V; the {part} runs on {lo:g} to {hi:g} V (datasheet){hint}"
        raise ModelError("init", "supply_v", said)
    top = v.get("range_max_g")
    if top is not None and v.get("range_g") is not None and v["range_g"] > top:
        raise ModelError(
            "init", "range_g", f"got +-{v['range_g']:g} g; the {part} measures +-{top:g} g (datasheet full scale)"
        )


def axis_densities(v: dict, axes: tuple[str, ...] | list[str]) -> list[float]:
    """Noise density of each axis [g/sqrt(Hz)]: the part's per-axis figure for an axis of that name (else of
    that place among the part's axes), else the one density given."""
    per = v.get("axis_noise_density_g_rthz") or {}
    names = list(per)
    out = []
    for i, a in enumerate(axes):
        if a in per:
            out.append(float(per[a]))
        elif i < len(names) and not set(axes) & set(names):
            out.append(float(per[names[i]]))
        else:
            out.append(float(v["noise_density_g_rthz"]))
    return out


def noise_R(density_g_rthz: float, bandwidth_hz: float, step_g: float) -> float:
    """R [(m/s^2)^2] of one axis: the analog noise over the output filter's equivalent noise bandwidth (one pole:
    pi/2 x -3 dB), plus the read-out's rounding, uniform over one step (step^2 / 12)."""
    noise_rms_g = density_g_rthz * math.sqrt(bandwidth_hz * math.pi / 2)
    return (noise_rms_g * G0) ** 2 + (step_g * G0) ** 2 / 12


@dataclass(frozen=True)
class NewModel:
    model: Model
    header: str  # comment lines for the top of the file: where each number came from
    next_steps: list[str]  # what to measure next, one line each

    @property
    def text(self) -> str:
        return dump_model(self.model, header=self.header)


def _need(values: dict, keys: tuple[str, ...], kind: str) -> None:
    missing = [k for k in keys if values.get(k) is None]
    if missing:
        raise ModelError("init", missing[0], f"required for a {kind} part ({', '.join(missing)} missing)")


def new_model(name: str, kind: str, rate_hz: float, axes: tuple[str, ...] | list[str], **given) -> NewModel:
    """A validated model for a part described by its datasheet (keys as in the model file, SI units).

    analog: supply_v, adc_bits, adc_ref_v (default supply_v: ratiometric), sensitivity_v_per_g, zero_g_v
    (default supply_v / 2); duty_cycle: timer_clock_hz, t2_period_s, zero_g_duty, duty_per_g; digital:
    lsb_per_g (int16 counts, read with --unit counts); calibrated: unit (g or m/s^2). Every kind: range_g,
    noise_density_g_rthz, bandwidth_hz, part. Refusals are the loader's one-line ModelError."""
    v = {k: x for k, x in given.items() if x is not None}
    if kind not in KINDS:
        raise ModelError("init", "kind", f"got {kind!r}; accepted: {', '.join(KINDS)}")
    _need(v, ("range_g", "noise_density_g_rthz", "bandwidth_hz"), kind)
    lines = [f"accelnav model written by `accelnav init` for {v.get('part') or 'a new part'} ({kind}).", ""]
    if v.get("note"):
        lines += [f"Datasheet figures: {v['note']}."]
    _check_limits(v)
    bw = v["bandwidth_hz"]
    if kind == "analog":
        _need(v, ("supply_v", "adc_bits", "sensitivity_v_per_g"), kind)
        v.setdefault("adc_ref_v", v["supply_v"])
        v.setdefault("zero_g_v", v["supply_v"] / 2)
        sensor = (
            "[sensor.analog]\n"
            f"supply_v = {float(v['supply_v'])!r}\nadc_bits = {int(v['adc_bits'])}\n"
            f"adc_ref_v = {float(v['adc_ref_v'])!r}\nsensitivity_v_per_g = {float(v['sensitivity_v_per_g'])!r}\n"
            f"zero_g_v = {float(v['zero_g_v'])!r}\n"
        )
        step_g = v["adc_ref_v"] / 2 ** int(v["adc_bits"]) / v["sensitivity_v_per_g"]
        step_what = f"ADC step {v['adc_ref_v']:g} V / 2^{int(v['adc_bits'])} / {v['sensitivity_v_per_g']:g} V/g"
    elif kind == "duty_cycle":
        _need(v, ("timer_clock_hz", "t2_period_s", "duty_per_g"), kind)
        v.setdefault("zero_g_duty", 0.5)
        sensor = (
            "[sensor.duty_cycle]\n"
            f"timer_clock_hz = {float(v['timer_clock_hz'])!r}\nt2_period_s = {float(v['t2_period_s'])!r}\n"
            f"zero_g_duty = {float(v['zero_g_duty'])!r}\nduty_per_g = {float(v['duty_per_g'])!r}\n"
        )
        counts = max(1, round(v["t2_period_s"] * v["timer_clock_hz"]))
        step_g = 1.0 / (counts * v["duty_per_g"])
        step_what = f"capture step 1 / ({counts} counts x {v['duty_per_g']:g} duty/g)"
    elif kind == "digital":
        _need(v, ("lsb_per_g",), kind)
        sensor = f'[sensor.calibrated]\nunit = "g"\nlsb_per_g = {float(v["lsb_per_g"])!r}\n'
        step_g = 1.0 / v["lsb_per_g"]
        step_what = f"output step 1 / {v['lsb_per_g']:g} LSB/g"
    else:
        unit = v.get("unit", "m/s^2")
        sensor = f'[sensor.calibrated]\nunit = "{unit}"\n'
        step_g = 0.0
        step_what = "no quantisation (calibrated samples)"
    # R: one per model, for every axis alike; the noisiest axis sets it (as fit-bias's R is the largest
    # of its axes), and the sensor's density is that axis's, so R follows from the file's own keys
    dens = axis_densities(v, axes)
    worst = max(range(len(dens)), key=dens.__getitem__)
    nd = dens[worst]
    R = noise_R(nd, bw, step_g)
    if len(set(dens)) > 1:
        each = ", ".join(f"{a} {d * 1e6:g}" for a, d in zip(axes, dens, strict=True))
        lines += [
            f"Noise density per axis: {each} ug/sqrt(Hz). The model holds one R for all axes: the noisiest, "
            f"{axes[worst]}, sets it and sensor.noise_density_g_rthz; the quieter axes' R is over-stated "
            f"(their filter trusts them less than it could).",
        ]
    lines += [
        f"R = ({nd:g} g/sqrt(Hz) x sqrt(pi/2 x {bw:g} Hz) x g0)^2 + ({step_what} x g0)^2 / 12 "
        f"= {R:.4g} (m/s^2)^2: the datasheet's noise density over the output filter, plus rounding.",
        f"sigma_n = {SIGMA_N:g} (hand-held motion) and sigma_eps = {SIGMA_EPS:g} are placeholders: "
        "`accelnav tune` and `accelnav fit-bias` measure them.",
        f"Bias c1 = c2 = 0, T = {T_BIAS:g} s are placeholders until `accelnav fit-bias` measures them; "
        "the bias prior's sigma (filter.initial_sigma[3]) is wide for that reason.",
        f"ranges.max_run_s = {STILL_RECORD_S:g} s: the still recording fit-bias needs (four warm-up time "
        "constants T), which the firmware's filter runs through too.",
        "Units: SI unless a key name says otherwise.",
    ]
    sig_eps0 = 0.1 * v["range_g"] * G0 / 3.6  # an uncalibrated zero-g: a tenth of the full scale, about 1 m/s^2
    axes_text = "".join(f'\n[[axes]]\nname = "{a}"\nc1 = 0.0\nc2 = 0.0\nT = {T_BIAS!r}\n' for a in axes)
    text = (
        f'[model]\nname = "{name}"\ndescription = "{v.get("part") or kind} at {rate_hz:g} Hz, datasheet noise"\n\n'
        f'[sensor]\nkind = "{"calibrated" if kind == "digital" else kind}"\npart = "{v.get("part", "")}"\n'
        f"range_g = {float(v['range_g'])!r}\nnoise_density_g_rthz = {float(nd)!r}\nbandwidth_hz = {float(bw)!r}\n\n"
        f"{sensor}\n[sampling]\nrate_hz = {float(rate_hz)!r}\n{axes_text}\n"
        f"[noise]\nsigma_n = {SIGMA_N!r}\nsigma_eps = {SIGMA_EPS!r}\nR = {float(f'{R:.6g}')!r}\n\n"
        "[ranges]\n" + "".join(f"{k} = {x!r}\n" for k, x in RANGES.items()) + "\n"
        f'[filter]\nform = "covariance"\ninitial_sigma = [0.0, 0.0, 0.05, {float(f"{sig_eps0:.3g}")!r}]\n'
    )
    import json

    for bad in (name, v.get("part", ""), *axes):  # strings reach TOML only as checked by the loader's rules
        if json.dumps(bad) != f'"{bad}"':
            raise ModelError("init", "name", f"got {ascii(bad)}; accepted: no quotes, backslashes or controls")
    model = loads_model(text, source="init")
    counts = " --unit counts" if kind in ("analog", "digital") else ""
    still = model.ranges.max_run_s  # what the written model's firmware is proved for: no more, and enough
    steps = [
        f"record the part still for {still / 60:g} min ({still:g} s, the model's ranges.max_run_s) from "
        f"power-on, then: accelnav fit-bias REC.csv --model THIS.toml{counts} --out FITTED.toml (the bias c1, c2, "
        "T and the noise figures)",
    ]
    if kind in ("analog", "duty_cycle"):
        steps.append(
            "record six still poses (each axis up, then down), then: accelnav calibrate POSES.csv --model "
            "FITTED.toml --out CAL.toml (zero-g and sensitivity per axis)"
        )
    steps.append(f"then smooth a motion recording: accelnav smooth RUN.csv --model CAL.toml{counts} --out RUN.npz")
    import textwrap

    header = "\n".join(w for line in lines for w in (textwrap.wrap(line, 100) or [""]))
    return NewModel(model=model, header=header, next_steps=steps)
