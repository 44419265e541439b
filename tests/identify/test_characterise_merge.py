"""accelnav.characterise, the library under ``accelnav fit-bias``: the bias constants and noise figures it
finds in a stationary recording and the model it merges them into (the embedded default, the run file's own
model, or a given one). The command's lines, files and refusals: tests/cli/test_fit_bias_cli.py."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from conftest import MODELS
from support.fit_bias_cases import ADIS, band_limited_phone, fine_model, sim_npz, warm_up, write_csv

import accelnav
from accelnav.data.recording import read_recording
from accelnav.identify.characterise import analyse_axis
from accelnav.model.load import DEFAULT_MODEL, G0, load_model


def test_warm_up_and_constant_bias_from_a_gzip_csv(tmp_path):
    # x: a warm-up (c1 = 8 mg, T = 40 s); y: a constant bias; both in g, gzip CSV with a time column.
    t = np.arange(24_000) / 100.0
    sigma = 0.01  # g
    x = warm_up(t, 0.008, 0.005, 40.0, sigma, 1)
    y = warm_up(t, 0.0, -0.012, 40.0, sigma, 2)
    ch = accelnav.characterise(write_csv(tmp_path / "rest.csv.gz", {"t_s": t, "acc_x_g": x, "acc_y_g": y}))
    rx, ry = ch.axes
    assert (rx.name, rx.column, rx.unit) == ("x", "acc_x_g", "g") and rx.fit.T_identified
    assert not ry.fit.T_identified  # a constant bias
    m = ch.model
    ax = m.axis("x")
    assert ax.c1 == pytest.approx(0.008 * G0, rel=0.1)
    assert ax.c2 == pytest.approx(0.005 * G0, abs=0.004)
    assert ax.T == pytest.approx(40.0, rel=0.2)
    ay = m.axis("y")
    assert ay.c1 == 0.0 and ay.c2 == pytest.approx(np.mean(y) * G0, rel=1e-5)
    assert ay.T == load_model(DEFAULT_MODEL).axis("y").T  # not identified: the base model's T is kept
    # white noise: the composite check finds the white R adequate over the band and keeps it
    assert not any(r.check.understated for r in ch.axes)
    # R = N^2 / Ts: for white noise the sample variance
    assert m.noise.R == pytest.approx((sigma * G0) ** 2, rel=0.1)
    assert m.noise.sigma_n == 1.0  # kept from the base model
    assert m.name == "rest_fit" and m.rate_hz == 100.0
    assert m.sensor == load_model(DEFAULT_MODEL).sensor


def test_sim_npz_merges_into_its_embedded_model(tmp_path, default_model):
    ax = default_model.axes
    model = fine_model(default_model, [dataclasses.replace(ax[0], c1=0.3, c2=0.05, T=40.0), ax[1]])
    npz = sim_npz(tmp_path / "run.npz", model, 200.0, 3)
    m = accelnav.characterise(npz, axes=["x"], sigma_n="paper").model
    assert m.sensor == model.sensor and m.name == model.name  # merged into the embedded model
    assert m.axis("y") == model.axis("y")  # an axis not fitted is left alone
    assert m.axis("x").c1 == pytest.approx(0.3, rel=0.1) and m.axis("x").T == pytest.approx(40.0, rel=0.2)
    assert m.noise.sigma_n != model.noise.sigma_n
    # the paper's rule for the AR(1) sensor noise: sqrt(var(diff(a)) / Ts)
    acc = np.load(npz)["accel"][:, 0]
    assert m.noise.sigma_n == pytest.approx(math.sqrt(np.var(np.diff(acc)) / model.Ts), rel=1e-5)


def test_given_model_is_the_base(tmp_path):
    t = np.arange(12_000) / 100.0
    rec = write_csv(
        tmp_path / "r.csv", {"time_ms": t * 1000, "accel_z_m_s2": warm_up(t, 0.0, 0.3, 1.0, 0.01, 4)}, gz=False
    )
    base = MODELS / "adxl202_duty.toml"
    m = accelnav.characterise(rec, base).model
    b = load_model(base)
    assert m.sensor == b.sensor and m.name == b.name and m.filter == b.filter
    assert [a.name for a in m.axes] == ["x", "y", "z"]  # z appended with the sensor's calibration
    assert m.axis("z").c2 == pytest.approx(0.3, abs=0.001) and m.axis("z").c1 == 0.0
    assert m.noise.sigma_n == b.noise.sigma_n


def test_band_limited_recording_is_flagged_and_R_raised(tmp_path):
    rec, true_band = band_limited_phone(tmp_path)
    ch = accelnav.characterise(rec)
    (r,) = ch.axes
    assert r.check.understated and r.check.R_chosen > r.check.R_white  # R raised to the band's R
    assert 0.7 * true_band < ch.model.noise.R < 1.5 * true_band


@pytest.fixture(scope="module")
def adis():
    if not ADIS.is_file():
        pytest.skip(f"the real recording is not here: {ADIS} (../shared/data is absent on this machine)")
    # its gyro columns make it an IMU log, which read_recording levels by default; a bias study reads the device's
    # own axes, as characterise and fit-bias do
    return read_recording(ADIS, level=False)


def test_real_recording_every_axis(adis):
    assert adis.axis_names == ("x", "y", "z") and adis.n == 1_000_000
    assert adis.rate_hz == pytest.approx(100.0, rel=1e-6)
    for name in adis.axis_names:
        r = analyse_axis(adis, name, min_duration_s=60.0, full_scale=None, lags=20)
        mg = G0 * 1e-3
        # what a first look found: 3.4 - 4.5 mg rms, Allan minimum 0.2 - 0.3 mg at 8 - 70 s
        assert 3.0 * mg < r.fit.sigma < 5.0 * mg
        assert 0.15 * mg < r.noise.terms.adev_min < 0.35 * mg
        assert 5.0 < r.noise.terms.tau_min < 100.0
        # the residuals of this sensor at rest are far from white (short-range correlation and flicker)
        assert not any(t.white for t in r.white.tests)
        assert r.fit.vif > 10
        if name == "z":
            assert r.fit.c2 == pytest.approx(-1.018 * G0, abs=0.01)  # gravity is part of the constant
        # spectral lines (0.57, 1.7, 10 Hz) are not white, GM, flicker or random walk: the composite misses
        # them, and says so rather than claiming a good fit
        assert r.composite.fit_poor
