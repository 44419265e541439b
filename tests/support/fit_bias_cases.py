"""Stationary recordings for the bias fit: a warm-up curve with white noise written as a (gzip) CSV, a
simulated run file with its embedded model, a fine-ADC model. Shared by tests/identify/test_characterise_merge.py
and the fit-bias command's tests (tests/cli/test_fit_bias_cli.py)."""

from __future__ import annotations

import dataclasses
import gzip
import math
from pathlib import Path

import numpy as np
from conftest import SHARED_DATA

from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.edit import revalidate

ADIS = SHARED_DATA / "adis16405_stationary" / "adis_16405_imu1.csv.gz"  # the real stationary recording


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


def sim_npz(path: Path, model, duration: float, seed: int) -> Path:
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


def fine_model(base, axes):
    an = dataclasses.replace(base.sensor.analog, adc_bits=16)
    sensor = dataclasses.replace(base.sensor, analog=an)
    return revalidate(dataclasses.replace(base, sensor=sensor, axes=tuple(axes)))


def same_model(a, b) -> bool:
    """Everything a model file says but its source, text and hash (what ``accelnav fit-bias`` writes is the
    library's model, read back)."""
    skip = {"source", "sha256", "text"}
    return all(getattr(a, f.name) == getattr(b, f.name) for f in dataclasses.fields(a) if f.name not in skip)


def band_limited_phone(tmp_path):
    """The issue's phone: 10 Hz, band-limited noise whose Allan curve rises to a hump near 3 s (white 8e-4
    m/s^2/sqrt(Hz) plus a Gauss-Markov part of sd 7e-3 m/s^2 and correlation time 1.5 s), 2 hours; and the
    true low-frequency R of that band."""
    from scipy import signal

    fs, n = 10.0, 72_000
    rng = np.random.default_rng(4)
    phi = math.exp(-1 / (fs * 1.5))
    gm = signal.lfilter([1.0], [1.0, -phi], rng.standard_normal(n) * 7e-3 * math.sqrt(1 - phi**2))
    y = rng.standard_normal(n) * 8e-4 * math.sqrt(fs) + gm
    t = np.arange(n) / fs
    # the white-noise R is N^2/Ts at tau = 1 s; the band's R must reach the true low-frequency level
    # (white + GM white-equivalent, 2 s^2 T, at tau >> T), which is what position error sees
    true_band = (8e-4**2 + 2 * 7e-3**2 * 1.5) * fs
    return write_csv(tmp_path / "phone.csv.gz", {"t_s": t, "acc_x_m_s2": y}, fmt="%.7g"), true_band
