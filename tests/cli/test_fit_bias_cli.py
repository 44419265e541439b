"""``accelnav fit-bias`` end to end, the model writer, the recording reader's refusals, the real recording."""

from __future__ import annotations

import dataclasses
import gzip
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import MODELS, SHARED_DATA

from accelnav.cli import main
from accelnav.data.recording import read_recording
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.identify.characterise import analyse_axis
from accelnav.model.edit import dump_model, revalidate, with_axis_bias, with_noise
from accelnav.model.load import DEFAULT_MODEL, G0, ModelError, load_model, loads_model

ADIS = SHARED_DATA / "adis16405_stationary" / "adis_16405_imu1.csv.gz"


# --------------------------------------------------------------------------
# The model writer


def _same_fields(a, b) -> list[str]:
    skip = {"source", "sha256", "text"}
    return [f.name for f in dataclasses.fields(a) if f.name not in skip and getattr(a, f.name) != getattr(b, f.name)]


@pytest.mark.parametrize("path", sorted(MODELS.glob("*.toml")), ids=lambda p: p.name)
def test_dump_model_round_trips_every_field(path):
    m = load_model(path)
    text = dump_model(m)
    back = loads_model(text)
    assert _same_fields(m, back) == []
    assert dump_model(back) == text  # canonical: a second pass changes nothing


def test_dump_model_keeps_odd_strings_and_overrides(default_model):
    name = 'quote " backslash \\ tab \t newline \n del \x7f unicode µ'
    m = dataclasses.replace(default_model, description=name)
    m = with_axis_bias(m, "z", -1e-17, -9.80665, 12345.678901234567)
    ax = dataclasses.replace(m.axes[0], sensitivity=0.0381, zero_g=2.4999)
    m = dataclasses.replace(m, axes=(ax, *m.axes[1:]))
    back = loads_model(dump_model(m, header="first line\nsecond line"))
    assert _same_fields(m, back) == []
    assert back.axis("z").T == 12345.678901234567 and back.axis("x").zero_g == 2.4999
    assert dump_model(m, header="first line\nsecond line").startswith("# first line\n# second line\n")


def test_edits_are_checked_by_the_loader(default_model):
    m = with_noise(with_axis_bias(default_model, "x", 0.1, 0.2, 30.0), R=0.5, sigma_eps=0.0)
    v = revalidate(m)
    assert v.axis("x").c1 == 0.1 and v.noise.R == 0.5 and v.noise.sigma_eps == 0.0 and v.noise.sigma_n == 1.0
    assert len(v.sha256) == 64 and v.text == dump_model(m)
    four = with_axis_bias(with_axis_bias(default_model, "z", 0, 0, 1.0), "w", 0, 0, 1.0)
    with pytest.raises(ModelError, match="accepted: 1 to 3"):
        revalidate(four)
    with pytest.raises(ModelError, match="full scale"):
        revalidate(with_axis_bias(default_model, "x", 400.0, 200.0, 1.0))


# --------------------------------------------------------------------------
# Recordings for the command


def write_csv(path: Path, columns: dict[str, np.ndarray], *, gz: bool = True, fmt: str = "%.9g") -> Path:
    names = list(columns)
    rows = np.column_stack([columns[n] for n in names])
    body = "\n".join(",".join(fmt % v for v in row) for row in rows)
    text = ",".join(names) + "\n" + body + "\n"
    if gz:
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


def warm_up(t, c1, c2, T, sigma, seed):
    return c1 * -np.expm1(-t / T) + c2 + sigma * np.random.default_rng(seed).standard_normal(len(t))


def _files(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.png"))


def test_csv_end_to_end(tmp_path, capsys):
    # x: a warm-up (c1 = 8 mg, T = 40 s); y: a constant bias; both in g, gzip CSV with a time column.
    t = np.arange(24_000) / 100.0
    sigma = 0.01  # g
    x = warm_up(t, 0.008, 0.005, 40.0, sigma, 1)
    y = warm_up(t, 0.0, -0.012, 40.0, sigma, 2)
    rec = write_csv(tmp_path / "rest.csv.gz", {"t_s": t, "acc_x_g": x, "acc_y_g": y})
    out = tmp_path / "fitted.toml"
    plots = tmp_path / "plots"
    assert main(["fit-bias", str(rec), "--out", str(out), "--plots", str(plots)]) == 0
    text = capsys.readouterr().out
    assert "axis x (column acc_x_g, in g)" in text and "T identified" in text
    assert "constant bias" in text and "Ljung-Box" in text and "cumulative periodogram" in text
    m = load_model(out)
    ax = m.axis("x")
    assert ax.c1 == pytest.approx(0.008 * G0, rel=0.1)
    assert ax.c2 == pytest.approx(0.005 * G0, abs=0.004)
    assert ax.T == pytest.approx(40.0, rel=0.2)
    ay = m.axis("y")
    assert ay.c1 == 0.0 and ay.c2 == pytest.approx(np.mean(y) * G0, rel=1e-5)
    assert ay.T == load_model(DEFAULT_MODEL).axis("y").T  # not identified: the base model's T is kept
    # white noise: the composite check finds the white R adequate over the band and keeps it
    assert "the white-noise R represents this band" in text and "understates the noise" not in text
    # R = N^2 / Ts: for white noise the sample variance
    assert m.noise.R == pytest.approx((sigma * G0) ** 2, rel=0.1)
    assert m.noise.sigma_n == 1.0  # kept from the base model
    assert m.name == "rest_fit" and m.rate_hz == 100.0
    assert m.sensor == load_model(DEFAULT_MODEL).sensor
    # the written file carries the provenance as comments
    assert out.read_text().startswith("# accelnav model written by accelnav fit-bias\n")
    pngs = _files(plots)
    assert [p.name for p in pngs] == sorted(
        f"{a}_{k}.png" for a in "xy" for k in ("fit", "spectrum", "allan", "acf", "noise_model")
    )
    assert all(p.stat().st_size > 5000 for p in pngs)


def _sim_npz(path: Path, model, duration: float, seed: int) -> Path:
    run = simulate(model, "stationary", duration, seed, initial_random=False)
    np.savez(
        path,
        format=np.array("accelnav-run/1"),
        model_toml=np.array(model.text),
        t=run.t,
        axis_names=np.array(run.axis_names),
        accel=run.accel,
        clipped=run.clipped,
    )
    return path


def _fine_model(base, axes):
    an = dataclasses.replace(base.sensor.analog, adc_bits=16)
    sensor = dataclasses.replace(base.sensor, analog=an)
    return revalidate(dataclasses.replace(base, sensor=sensor, axes=tuple(axes)))


def test_sim_npz_merges_into_its_embedded_model(tmp_path, capsys, default_model):
    ax = default_model.axes
    model = _fine_model(default_model, [dataclasses.replace(ax[0], c1=0.3, c2=0.05, T=40.0), ax[1]])
    npz = _sim_npz(tmp_path / "run.npz", model, 200.0, 3)
    out = tmp_path / "m.toml"
    assert main(["fit-bias", str(npz), "--axis", "x", "--out", str(out), "--sigma-n", "paper"]) == 0
    text = capsys.readouterr().out
    m = load_model(out)
    assert m.sensor == model.sensor and m.name == model.name  # merged into the embedded model
    assert m.axis("y") == model.axis("y")  # an axis not fitted is left alone
    assert m.axis("x").c1 == pytest.approx(0.3, rel=0.1) and m.axis("x").T == pytest.approx(40.0, rel=0.2)
    assert m.noise.sigma_n != model.noise.sigma_n and "from the paper's rule" in text
    # the paper's rule for the AR(1) sensor noise: sqrt(var(diff(a)) / Ts)
    acc = np.load(npz)["accel"][:, 0]
    assert m.noise.sigma_n == pytest.approx(math.sqrt(np.var(np.diff(acc)) / model.Ts), rel=1e-5)


def test_given_model_is_the_base(tmp_path, capsys):
    t = np.arange(12_000) / 100.0
    rec = write_csv(
        tmp_path / "r.csv", {"time_ms": t * 1000, "accel_z_m_s2": warm_up(t, 0.0, 0.3, 1.0, 0.01, 4)}, gz=False
    )
    out = tmp_path / "m.toml"
    base = MODELS / "adxl202_duty.toml"
    assert main(["fit-bias", str(rec), "--model", str(base), "--out", str(out)]) == 0
    m = load_model(out)
    b = load_model(base)
    assert m.sensor == b.sensor and m.name == b.name and m.filter == b.filter
    assert [a.name for a in m.axes] == ["x", "y", "z"]  # z appended with the sensor's calibration
    assert m.axis("z").c2 == pytest.approx(0.3, abs=0.001) and m.axis("z").c1 == 0.0
    assert m.noise.sigma_n == b.noise.sigma_n


# --------------------------------------------------------------------------
# Refusals: one line on stderr, exit status 2, saying what and where


def _good(n=12_000):
    t = np.arange(n) / 100.0
    return t, warm_up(t, 0.0, 0.01, 1.0, 0.005, 5)


def _case_nan(tmp):
    t, x = _good()
    x[1234] = np.nan
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "first at sample 1234 (t = 12.34 s)"


def _case_empty_cell(tmp):
    t, x = _good()
    p = write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}, gz=False)
    lines = p.read_text().splitlines()
    lines[101] = lines[101].split(",")[0] + ","
    p.write_text("\n".join(lines) + "\n")
    return [p], "line 102, column 'acc_x_g' is empty"


def _case_gap(tmp):
    t, x = _good()
    t[5000:] += 0.5
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "gap in time of 0.51 s at t = 49.99 s"


def _case_backwards(tmp):
    t, x = _good()
    t[[700, 701]] = t[[701, 700]]
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "time does not increase at sample 701"


def _case_constant(tmp):
    t, _ = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": np.full(len(t), 0.02)})], "the signal is constant"


def _case_rail(tmp):
    t, x = _good()
    x = np.minimum(x, 0.012)  # a rail just above the mean: many samples pile up there
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "sit at the maximum"


def _case_flagged(tmp, default_model):
    npz = _sim_npz(tmp / "run.npz", default_model, 80.0, 1)
    d = dict(np.load(npz))
    d["clipped"][4321, 0] = True
    np.savez(npz, **d)
    return [npz], "1 samples are flagged clipped, the first at sample 4321"


def _case_full_scale(tmp):
    t, _ = _good()
    x = np.where(np.arange(len(t)) % 7 == 0, 2.0, 1.9)  # the ADXL202's 2 g rail
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}), "--model", str(MODELS / "adxl202_duty.toml")], (
        "at the sensor's full scale"
    )


def _case_short(tmp):
    t, x = _good(3000)
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x})], "too short: 29.99 s"


def _case_no_column(tmp):
    t, x = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}), "--axis", "q"], "no column 'q'"


def _case_unknown_unit(tmp):
    t, x = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "acc_x_g": x}), "--unit", "furlong"], "unit 'furlong' is not known"


def _case_no_unit(tmp):
    t, x = _good()
    return [write_csv(tmp / "r.csv", {"t_s": t, "accx": x})], "does not say its unit"


def _case_no_time(tmp):
    _, x = _good()
    return [write_csv(tmp / "r.csv", {"acc_x_g": x})], "no time column"


def _case_missing_file(tmp):
    return [str(tmp / "nothing.csv")], "no such file"


def _case_not_csv(tmp):
    p = tmp / "r.bin"
    p.write_bytes(bytes(range(256)) * 4)
    return [p], "not UTF-8"


CASES = {
    "nan": _case_nan,
    "empty cell": _case_empty_cell,
    "gap": _case_gap,
    "time backwards": _case_backwards,
    "constant": _case_constant,
    "rail pile-up": _case_rail,
    "flagged clipped": _case_flagged,
    "full scale": _case_full_scale,
    "too short": _case_short,
    "no column": _case_no_column,
    "unknown unit": _case_unknown_unit,
    "no unit": _case_no_unit,
    "no time": _case_no_time,
    "missing file": _case_missing_file,
    "not csv": _case_not_csv,
}


@pytest.mark.parametrize("case", list(CASES))
def test_refusals_are_one_line(case, tmp_path, capsys, default_model):
    make = CASES[case]
    args, expected = make(tmp_path, default_model) if case == "flagged clipped" else make(tmp_path)
    out = tmp_path / "never.toml"
    status = main(["fit-bias", *[str(a) for a in args], "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.startswith("accelnav: error: ") and err.count("\n") == 1, err
    assert expected in err, err
    assert "Traceback" not in err and not out.exists()


# --------------------------------------------------------------------------
# The real stationary recording (ADIS16405, 1e6 samples at 100 Hz, in g)


@pytest.fixture(scope="module")
def adis():
    if not ADIS.is_file():
        pytest.skip(f"the real recording is not here: {ADIS} (../shared/data is absent on this machine)")
    return read_recording(ADIS)


def test_real_recording_every_axis(adis, tmp_path, capsys):
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
    out = tmp_path / "adis.toml"
    assert main(["fit-bias", str(ADIS), "--out", str(out), "--axis", "z", "--plots", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "axis z (column acc_z_g, in g)" in text
    assert "WARNING: poor fit" in text and "fits this band poorly" in text
    data = tomllib.loads(out.read_text())
    assert [a["name"] for a in data["axes"]] == ["x", "y", "z"]
    assert len(_files(tmp_path)) == 5


def test_band_limited_recording_is_flagged_and_R_raised(tmp_path, capsys):
    # the phone: 10 Hz, band-limited noise whose Allan curve rises to a hump near 3 s (white 8e-4
    # m/s^2/sqrt(Hz) plus a Gauss-Markov part of sd 7e-3 m/s^2 and correlation time 1.5 s), 2 hours
    from scipy import signal

    fs, n = 10.0, 72_000
    rng = np.random.default_rng(4)
    phi = math.exp(-1 / (fs * 1.5))
    gm = signal.lfilter([1.0], [1.0, -phi], rng.standard_normal(n) * 7e-3 * math.sqrt(1 - phi**2))
    y = rng.standard_normal(n) * 8e-4 * math.sqrt(fs) + gm
    t = np.arange(n) / fs
    rec = write_csv(tmp_path / "phone.csv.gz", {"t_s": t, "acc_x_m_s2": y}, fmt="%.7g")
    out = tmp_path / "phone.toml"
    assert main(["fit-bias", str(rec), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "WARNING: the white-noise R understates the noise in this band" in text
    m = load_model(out)
    # the white-noise R is N^2/Ts at tau = 1 s; the band's R must reach the true low-frequency level
    # (white + GM white-equivalent, 2 s^2 T, at tau >> T), which is what position error sees
    true_band = (8e-4**2 + 2 * 7e-3**2 * 1.5) * fs
    assert 0.7 * true_band < m.noise.R < 1.5 * true_band
    assert "R raised to the band's R" in out.read_text()
