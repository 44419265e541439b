"""Models the generator refuses, each with one clear line naming the key or variable, its range and the bits.

The first group is unrepresentable in the generated C (refused by codegen's
range analysis); the second is malformed (refused by the model loader on the
codegen path, through the CLI, exit status 2).
"""

from __future__ import annotations

import pytest

from accelnav.codegen.emit_c import emit
from accelnav.model.load import ModelError, load_model, loads_model

BASE = open(load_model().source).read()


def variant(*pairs: tuple[str, str], short: bool = True) -> str:
    text = BASE
    for old, new in pairs:
        assert old in text, old
        text = text.replace(old, new)
    if short:  # keep the Riccati short: these refusals do not depend on the run length
        text = text.replace("max_run_s = 3600.0", "max_run_s = 60.0")
    return text


UNREPRESENTABLE = [
    ("max_position_m = 20000.0", "max_position_m = 1e30", "ranges.max_position_m: range +-2e+30 m needs 102 bits"),
    ("max_velocity_m_s = 60.0", "max_velocity_m_s = 1e25", "ranges.max_velocity_m_s: range +-2e+23 m needs 79 bits"),
    ("R = 0.0160", "R = 1e-13", "noise.R: R = 1e-13 is 0 LSB of the covariance format"),
    ("R = 0.0160", "R = 2.3e-6", "noise.R: R = 2.3e-06 is too small for the innovation range"),
    ("R = 0.0160", "R = 1e12", "covariance c_a = P_aa + P_ae (and S): range +-2e+12"),
    ("sigma_n = 1.0", "sigma_n = 1e7", "covariance c_r = P_ra + P_re: range"),
    (
        "initial_sigma = [0.0, 0.0, 0.05, 0.05]",
        "initial_sigma = [0.0, 0.0, 1e6, 0.05]",
        "covariance c_r = P_ra + P_re: range +-6.25e+10",
    ),
    ("sigma_eps = 1.0e-3", "sigma_eps = 1e7", "needs"),
]


@pytest.mark.parametrize("old, new, message", UNREPRESENTABLE)
def test_unrepresentable(old, new, message):
    with pytest.raises(ModelError) as exc:
        emit(loads_model(variant((old, new)), source="bad.toml"))
    text = str(exc.value)
    assert text.startswith("bad.toml: ")
    assert message in text
    assert "\n" not in text
    if "needs" in text:
        assert "bits" in text


def test_run_too_long_for_the_generator():
    """(Also far beyond the 31-bit sample counter, which the generator's own limit stays below; both keys at
    the most the loader accepts, which alone bounds neither the samples nor the generator's time.)"""
    text = variant(("max_run_s = 3600.0", "max_run_s = 1e6"), ("rate_hz = 100.0", "rate_hz = 1e5"), short=False)
    with pytest.raises(ModelError, match=r"sampling.rate_hz x ranges.max_run_s: 100000 Hz x 1e\+06 s = 1e\+11 samples"):
        emit(loads_model(text, source="bad.toml"))


def test_duty_period_too_many_counts():
    text = BASE.replace('kind = "analog" ', 'kind = "duty_cycle"').replace("range_g = 50.0", "range_g = 4.0")
    a, b = text.index("[sensor.analog]"), text.index("[sampling]")
    text = (
        text[:a]
        + "[sensor.duty_cycle]\ntimer_clock_hz = 1.0e9\nt2_period_s = 1.0\nduty_per_g = 0.125\n\n"
        + text[b:].replace("rate_hz = 100.0", "rate_hz = 1.0")
    )
    text = text.replace("zero_g_v = 2.501\n", "").replace("max_run_s = 3600.0", "max_run_s = 60.0")
    with pytest.raises(ModelError, match=r"sensor.duty_cycle.t2_period_s: T2 up to 1.25e\+09 counts needs 31 bits"):
        emit(loads_model(text, source="bad.toml"))


MALFORMED = [
    ('form = "covariance"', 'form = "kalman"', "filter.form: got 'kalman'; accepted: 'covariance', 'gain_schedule'"),
    ("R = 0.0160", "R = -1.0", "noise.R: got -1; accepted"),
    ("rate_hz = 100.0", "rate_hz = 0.0", "sampling.rate_hz: got 0; accepted"),
    ('name = "x"', 'name = "x-axis"', "axes[0].name: got 'x-axis'; accepted: a C identifier"),
    ("adc_bits = 12", "adc_bits = 40", "sensor.analog.adc_bits: expected an integer from 6 to 24, got 40"),
    ("max_run_s = 3600.0", 'max_run_s = "long"', "ranges.max_run_s: expected a number, got a string"),
    ("c1 = 0.08", "c1 = 900.0", "axes[0].c1: |c1| + |c2| exceeds the sensor's full scale"),
    ("[noise]", "[noise]\ngain = 2.0", "noise.gain: unknown key"),
]


@pytest.mark.parametrize("old, new, message", MALFORMED)
def test_malformed_via_cli(old, new, message, tmp_path, capsys):
    from accelnav.cli import main

    path = tmp_path / "bad.toml"
    path.write_text(variant((old, new)))
    assert main(["codegen", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"accelnav: error: {path}: ")
    assert message in err
    assert "\n" not in err
    assert not (tmp_path / "out").exists()
