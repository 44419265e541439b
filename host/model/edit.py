"""Write a :class:`codegen.model.Model` back as TOML, and edit models without losing a field.

:func:`dump_model` is the inverse of :func:`codegen.model.loads_model`: for
every valid model ``m``, ``loads_model(dump_model(m))`` equals ``m`` in every
field (``source``, ``sha256`` and ``text`` describe the text, so they are the
new text's). The text is canonical: tables and keys in one fixed order,
floats in Python's shortest round-trip form, per-axis calibration written
only where it differs from the sensor's value, a unit comment on each key. It
is a pure function of the model (no time stamp), so writing the same model
twice gives the same bytes.

The editing helpers return new models (``dataclasses.replace`` on the frozen
dataclasses); :func:`revalidate` passes the result through the loader, so an
edit that breaks a rule of the model file (|c1| + |c2| above full scale, four
axes) is refused with the loader's own one-line message.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

from accelnav.fileio import write_text

from .load import Axis, Model, loads_model


def _float(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write the non-finite number {x} to a model file")
    return repr(x)


def _str(s: str) -> str:
    # A JSON string is a valid TOML basic string once DEL is escaped as well.
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def _lines(pairs: list[tuple[str, str, str]]) -> list[str]:
    width = max(len(k) + 3 + len(v) for k, v, _ in pairs)
    out = []
    for key, value, comment in pairs:
        text = f"{key} = {value}"
        out.append(f"{text:<{width}}  # {comment}" if comment else text)
    return out


def dump_model(model: Model, header: str = "") -> str:
    """Canonical TOML text of ``model``; ``header`` lines (if any) are written first as comments."""
    s = model.sensor
    out: list[str] = []
    if header:
        out += [f"# {line}".rstrip() for line in header.splitlines()]
        out.append("")
    out.append("[model]")
    out += _lines([("name", _str(model.name), ""), ("description", _str(model.description), "")])
    out += ["", "[sensor]"]
    out += _lines(
        [
            ("kind", _str(s.kind), "analog (ADC), duty_cycle (timer capture) or calibrated"),
            ("part", _str(s.part), ""),
            ("range_g", _float(s.range_g), "full scale, +-g"),
            ("noise_density_g_rthz", _float(s.noise_density_g_rthz), "g/sqrt(Hz), one-sided"),
            ("bandwidth_hz", _float(s.bandwidth_hz), "output filter, Hz"),
        ]
    )
    if s.kind == "calibrated":
        sens_key = zero_key = None
        sens_default = zero_default = None
        out += ["", "[sensor.calibrated]"]
        out += _lines([("unit", _str(s.calibrated.unit), "unit of the samples: g or m/s^2")])
        if s.calibrated.lsb_per_g > 0:
            out += _lines([("lsb_per_g", _float(s.calibrated.lsb_per_g), "counts per g of the digital output")])
    elif s.kind == "analog":
        a = s.analog
        sens_key, zero_key = "sensitivity_v_per_g", "zero_g_v"
        sens_default, zero_default = a.sensitivity_v_per_g, a.zero_g_v
        out += ["", "[sensor.analog]"]
        out += _lines(
            [
                ("supply_v", _float(a.supply_v), "V"),
                ("adc_bits", str(int(a.adc_bits)), ""),
                ("adc_ref_v", _float(a.adc_ref_v), "V"),
                ("sensitivity_v_per_g", _float(a.sensitivity_v_per_g), "V/g"),
                ("zero_g_v", _float(a.zero_g_v), "V"),
            ]
        )
    else:
        d = s.duty_cycle
        sens_key, zero_key = "duty_per_g", "zero_g_duty"
        sens_default, zero_default = d.duty_per_g, d.zero_g_duty
        out += ["", "[sensor.duty_cycle]"]
        out += _lines(
            [
                ("timer_clock_hz", _float(d.timer_clock_hz), "Hz"),
                ("t2_period_s", _float(d.t2_period_s), "s"),
                ("zero_g_duty", _float(d.zero_g_duty), "duty at 0 g"),
                ("duty_per_g", _float(d.duty_per_g), "duty per g"),
            ]
        )
    out += ["", "[sampling]"]
    out += _lines([("rate_hz", _float(model.rate_hz), "Hz")])
    for ax in model.axes:
        out += ["", "[[axes]]"]
        pairs = [
            ("name", _str(ax.name), ""),
            ("c1", _float(ax.c1), "m/s^2, eps(t) = c1 (1 - exp(-t/T)) + c2"),
            ("c2", _float(ax.c2), "m/s^2"),
            ("T", _float(ax.T), "s"),
        ]
        if sens_key and ax.sensitivity != sens_default:
            pairs.append((sens_key, _float(ax.sensitivity), "this axis's calibration"))
        if zero_key and ax.zero_g != zero_default:
            pairs.append((zero_key, _float(ax.zero_g), "this axis's calibration"))
        out += _lines(pairs)
    n = model.noise
    out += ["", "[noise]"]
    out += _lines(
        [
            ("sigma_n", _float(n.sigma_n), "white-jerk intensity, m/s^2/sqrt(s)"),
            ("sigma_eps", _float(n.sigma_eps), "bias random walk, m/s^2/sqrt(s)"),
            ("R", _float(n.R), "variance of one acceleration sample, (m/s^2)^2"),
        ]
    )
    r = model.ranges
    out += ["", "[ranges]"]
    out += _lines(
        [
            ("max_velocity_m_s", _float(r.max_velocity_m_s), "m/s"),
            ("max_position_m", _float(r.max_position_m), "m"),
            ("max_run_s", _float(r.max_run_s), "s"),
        ]
    )
    f = model.filter
    out += ["", "[filter]"]
    sig = "[" + ", ".join(_float(v) for v in f.initial_sigma) + "]"
    out += _lines(
        [
            ("form", _str(f.form), "covariance or gain_schedule"),
            ("initial_sigma", sig, "one-sigma [r, u, a, eps] at sample 0"),
        ]
    )
    return "\n".join(out) + "\n"


def revalidate(model: Model, source: str = "<edited model>") -> Model:
    """The model as the loader sees its canonical text (fresh ``sha256`` and ``text``); refuses a broken edit."""
    return loads_model(dump_model(model), source=source)


def with_axis_bias(model: Model, name: str, c1: float, c2: float, T: float) -> Model:
    """``model`` with axis ``name``'s bias constants replaced, or a new axis appended with the sensor's calibration."""
    axes = list(model.axes)
    for i, ax in enumerate(axes):
        if ax.name == name:
            axes[i] = dataclasses.replace(ax, c1=float(c1), c2=float(c2), T=float(T))
            return dataclasses.replace(model, axes=tuple(axes))
    s = model.sensor
    if s.kind == "calibrated":
        sens, zero = 1.0, 0.0
    elif s.kind == "analog":
        sens, zero = s.analog.sensitivity_v_per_g, s.analog.zero_g_v
    else:
        sens, zero = s.duty_cycle.duty_per_g, s.duty_cycle.zero_g_duty
    axes.append(Axis(name=name, c1=float(c1), c2=float(c2), T=float(T), sensitivity=sens, zero_g=zero))
    return dataclasses.replace(model, axes=tuple(axes))


def warm_started(model: Model) -> Model:
    """``model`` for a recording that begins after the warm-up: each axis's bias starts at its settled value.

    eps(t) = c1 (1 - exp(-t/T)) + c2 assumes sample 0 is power-on; long after it the bias sits at c1 + c2.
    Moving all of it into c2 (c1 = 0) puts the prior at c1 + c2 and keeps the recursion's fixed point
    (b depends on c1 + c2 only), so nothing else of the filter changes.
    """
    axes = tuple(dataclasses.replace(ax, c1=0.0, c2=ax.c1 + ax.c2) for ax in model.axes)
    return dataclasses.replace(model, axes=axes)


def with_noise(model: Model, **values: float) -> Model:
    """``model`` with some of sigma_n, sigma_eps, R replaced."""
    return dataclasses.replace(
        model, noise=dataclasses.replace(model.noise, **{k: float(v) for k, v in values.items()})
    )


def save_model(path: str | Path, model: Model, header: str = "") -> Model:
    """Write ``model`` as TOML to ``path``, whole or not at all; returns the model as read back.

    The text is read back through the loader before anything is written, so a model the loader would
    refuse never reaches the disk (the refusal names ``path``). ``header`` becomes comment lines on top.
    """
    text = dump_model(model, header=header)
    saved = loads_model(text, source=str(path))
    write_text(path, text)
    return saved
