"""Issue 23 (b): clocks. A jittery 200 Hz clock is read onto its grid; --rate with a time column is
checked or overrides, saying so; a millisecond clock is refused in one line or converted with
--time-unit ms by every command that takes a time column."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MODELS
from support.cli import run_cli as _run

from accelnav.data.recording import read_recording
from accelnav.data.runfile import load_run
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import G0, load_model

FOOT = MODELS / "foot_imu.toml"  # 200 Hz, calibrated, axes x and y


def _write(path, t, accel, t_name="t", cols=("ax", "ay")):
    lines = [",".join((t_name, *cols))] + [
        f"{float(ti)!r},{float(a)!r},{float(b)!r}" for ti, (a, b) in zip(t, accel, strict=True)
    ]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def walk():
    return simulate(load_model(FOOT), "walking", 20.0, 5)


def _bunched(t):
    """Stamps given on arrival: 3 samples at a time every 15 ms, 0.3 ms apart, up to 3 periods late."""
    i = np.arange(len(t))
    return t[0] + (i // 3 + 1) * 0.015 + (i % 3) * 3e-4


def _jittered(t, rng):
    """Each stamp within +-2.4 ms of its 5 ms grid point."""
    return t + rng.uniform(-2.4e-3, 2.4e-3, len(t)) * (np.arange(len(t)) > 0)


@pytest.mark.parametrize("kind", ["bunched", "jittered"])
def test_a_jittery_200_hz_clock_is_read_onto_its_grid(walk, tmp_path, capsys, kind):
    stamps = _bunched(walk.t) if kind == "bunched" else _jittered(walk.t, np.random.default_rng(3))
    steps = np.diff(stamps)
    assert steps.min() < 1e-3 and (steps.max() > 10e-3 or kind == "jittered")
    path = _write(tmp_path / "j.csv", stamps, walk.accel)
    rec = read_recording(path, axes=["ax", "ay"], unit="m/s^2")
    assert rec.rate_hz == 200.0
    np.testing.assert_allclose(np.diff(rec.t), 1 / 200.0, rtol=1e-9)
    assert len(rec.notes) == 1 and "jitters" in rec.notes[0] and "200 Hz grid" in rec.notes[0]
    status, out, err = _run(
        ["smooth", path, "--model", FOOT, "--axis", "ax", "--axis", "ay", "--full", "--out", tmp_path / "o.npz"], capsys
    )
    assert status == 0, err
    assert "jitters" in out
    arrays, _ = load_run(tmp_path / "o.npz")
    assert len(arrays["t"]) == len(walk.t) and not arrays["clipped"].any()
    np.testing.assert_allclose(arrays["accel"], walk.accel)  # every sample in its own place


def test_a_clock_that_fits_no_rate_is_refused_saying_how_to_resample(walk, tmp_path, capsys):
    rng = np.random.default_rng(4)
    stamps = np.cumsum(rng.uniform(0.5e-3, 12e-3, len(walk.t)))  # a free-running clock: no grid at all
    path = _write(tmp_path / "free.csv", stamps, walk.accel)
    status, _, err = _run(
        ["filter", path, "--model", FOOT, "--axis", "ax", "--axis", "ay", "--out", tmp_path / "f.npz"], capsys
    )
    assert status == 2 and err.count("\n") == 1
    assert "fits no fixed sample rate" in err and "resample" in err and "--rate HZ" in err


def test_rate_with_a_time_column_is_checked_or_overrides_and_says_which(walk, tmp_path, capsys):
    path = _write(tmp_path / "ok.csv", walk.t, walk.accel)
    argv = ["smooth", path, "--model", FOOT, "--axis", "ax", "--axis", "ay", "--full", "--out", tmp_path / "o.npz"]
    status, out, err = _run([*argv, "--rate", "200"], capsys)
    assert status == 0, err
    assert "--rate 200 Hz checked against the time column 't': it fits" in out
    # a logger whose clock runs 1.5 % fast: its stamps say 203 Hz; --rate 200 overrides them, explicitly
    fast = _write(tmp_path / "fast.csv", walk.t / 1.015, walk.accel)
    argv[1] = fast
    status, out, err = _run([*argv, "--rate", "200"], capsys)
    assert status == 0, err
    assert "--rate 200 Hz overrides the time column 't'" in out and "consecutive at 200 Hz" in out
    arrays, _ = load_run(tmp_path / "o.npz")
    np.testing.assert_allclose(arrays["t"], walk.t, atol=1e-9)


@pytest.fixture(scope="module")
def millis(tmp_path_factory):
    """A 70 s stationary 100 Hz recording of the default model's two axes with a millisecond clock."""
    model = load_model(None)
    run = simulate(model, "stationary", 70.0, 2)
    path = tmp_path_factory.mktemp("ms") / "still.csv"
    return _write(path, np.rint(run.t * 1000.0), run.accel / G0, t_name="millis", cols=("acc_x_g", "acc_y_g"))


COMMANDS = {
    "fit-bias": ["fit-bias", "{p}", "--out", "{o}/m.toml"],
    "filter": ["filter", "{p}", "--out", "{o}/f.npz"],
    "smooth": ["smooth", "{p}", "--full", "--out", "{o}/s.npz"],
    "tune": ["tune", "{p}", "--figures", "R", "--max-evaluations", "10", "--out", "{o}/t.toml"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_millisecond_clock_is_refused_in_one_line_or_converted(millis, tmp_path, capsys, command):
    argv = [a.format(p=millis, o=tmp_path) for a in COMMANDS[command]] + ["--time-column", "millis"]
    status, out, err = _run(argv, capsys)
    assert status == 2 and err.count("\n") == 1, err
    assert "looks like milliseconds" in err and "--time-unit ms" in err
    assert not any(tmp_path.iterdir())  # nothing written
    status, out, err = _run([*argv, "--time-unit", "ms"], capsys)
    assert status == 0, err
    if command == "fit-bias":
        assert load_model(tmp_path / "m.toml").rate_hz == 100.0
