"""Simulated parts for the calibration: the nominal model, a 'true' part off it, tumbles recorded on the true
part and converted with the nominal calibration. Shared by tests/identify/test_calibrate.py,
tests/cli/test_calibrate_cli.py and bench/coverage/coverage_calibrate.py."""

from __future__ import annotations

import dataclasses

import numpy as np

from accelnav.hil_sim.sim.sensor import simulate
from accelnav.hil_sim.sim.trajectories import TUMBLE_HOLD_S, TUMBLE_TURN_S, tumble_poses
from accelnav.identify.calibrate import calibrate, detect_poses
from accelnav.identify.calibration import steps_and_noise
from accelnav.model.design import input_conversion
from accelnav.model.edit import revalidate, with_axis_bias, with_noise
from accelnav.model.load import DEFAULT_MODEL, G0, load_model

POSE_S = TUMBLE_HOLD_S + TUMBLE_TURN_S


def nominal(n_axes: int = 2):
    """The default model with no warm-up and a small bias walk: the calibration's constant-offset assumption holds."""
    m = load_model(DEFAULT_MODEL)
    if n_axes == 3:
        m = with_axis_bias(m, "z", 0.0, 0.0, 300.0)
    m = dataclasses.replace(
        with_noise(m, sigma_eps=1e-4), axes=tuple(dataclasses.replace(a, c1=0.0, c2=0.0) for a in m.axes)
    )
    return revalidate(m)


def perturbed(nom, rng):
    """A 'true' part: zero-g within +-5 mV (+-0.13 g) and sensitivity within +-3 % of the nominal."""
    axes = tuple(
        dataclasses.replace(
            a, zero_g=a.zero_g + rng.uniform(-0.005, 0.005), sensitivity=a.sensitivity * (1 + rng.uniform(-0.03, 0.03))
        )
        for a in nom.axes
    )
    return revalidate(dataclasses.replace(nom, axes=axes))


def truth_offset_scale(nom, true, i):
    a0, a1 = nom.axes[i], true.axes[i]
    return (a1.zero_g - a0.zero_g) / a0.sensitivity * G0, a1.sensitivity / a0.sensitivity


def any_recording(nom, true, seed: int, n_poses: int = 12):
    """tumble_any on the true 3-axis part, converted with the nominal calibration."""
    run = simulate(true, "tumble_any", n_poses * POSE_S, seed, initial_random=False)
    return run, np.column_stack([input_conversion(nom, i).accel(run.code[:, i]) for i in range(len(nom.axes))])


def calibrate_any(nom, acc):
    steps, noise = steps_and_noise(nom)
    poses = detect_poses(acc, nom.rate_hz, steps=steps, noise_sd=noise)
    return calibrate(poses, tuple(a.name for a in nom.axes))


def tumble_recording(nom, true, seed: int, duration: float | None = None):
    """Tumble on the true part, converted with the nominal calibration (what the user's recording holds)."""
    n = len(nom.axes)
    duration = duration or len(tumble_poses(n)) * POSE_S
    run = simulate(true, "tumble", duration, seed, initial_random=False)
    acc = np.column_stack([input_conversion(nom, i).accel(run.code[:, i]) for i in range(n)])
    return run, acc


def save_g_csv(path, t, acc, fmt: str = "%.8g"):
    """A recording as a user's logger writes it: t_s and one acc_<axis>_g column per axis (x, y, z)."""
    header = ",".join(["t_s", *(f"acc_{n}_g" for n in "xyz"[: acc.shape[1]])])
    np.savetxt(path, np.column_stack([t, acc / G0]), delimiter=",", header=header, comments="", fmt=fmt)
    return path


def nominal_file(tmp_path, n_axes: int = 2):
    """(the nominal model, its file): what ``accelnav calibrate --model`` is given."""
    from accelnav.model.edit import dump_model

    nom = nominal(n_axes)
    path = tmp_path / f"nominal{n_axes}.toml"
    path.write_text(dump_model(nom))
    return nom, path
