"""fit-bias on a quiet part read through a coarse ADC step: an ADXL335 at 3.3 V on the 5 V-referenced 10-bit
ADC of an Uno (a step of 14.8 mg against 1.3 to 2.7 mg of noise), simulated. The still signal sits on one or two
codes: not clipping; the bias comes with intervals that hold the truth, and no noise figure is made up."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.identify.biasfit import fit_bias
from accelnav.identify.characterise import characterise
from accelnav.model.edit import revalidate
from accelnav.model.load import load_model

sensor = pytest.importorskip("accelnav.hil_sim.sim.sensor")

INIT = ["init", "--part", "adxl335", "--supply", "3.3", "--adc-ref", "5", "--adc-bits", "10", "--rate", "100"]
WARM = ((0.3, -0.2), (0.2, 0.0), (0.1, 0.2))  # (c1, c2) per axis, m/s^2, T = 60 s: one to three steps of warm-up


@pytest.fixture(scope="module")
def uno(tmp_path_factory):
    """(described model file, the part as it is, its still run from power-on, the counts CSV)."""
    d = tmp_path_factory.mktemp("uno")
    described = d / "adxl335_uno.toml"
    assert main([*INIT, "--out", str(described)]) == 0
    m = load_model(described)
    axes = tuple(dataclasses.replace(a, c1=c1, c2=c2, T=60.0) for a, (c1, c2) in zip(m.axes, WARM, strict=True))
    real = revalidate(dataclasses.replace(m, axes=axes))
    run = sensor.simulate(real, "stationary", 600.0, seed=2, initial_random=False)  # eps from c2 at t = 0
    path = d / "still.csv"
    cols = "t," + ",".join(f"acc_{a.name}_counts" for a in m.axes)
    np.savetxt(path, np.column_stack([run.t, run.code]), delimiter=",", header=cols, comments="",
               fmt=["%.6f", "%d", "%d", "%d"])  # fmt: skip
    return described, real, run, path


def test_the_still_part_sits_on_a_few_codes(uno):
    _, _, run, _ = uno
    for j in range(3):
        settled = run.code[-20000:, j]
        _, counts = np.unique(settled, return_counts=True)
        assert np.sort(counts)[-2:].sum() >= 0.95 * len(settled)  # one or two codes hold the settled part


def test_fit_bias_accepts_and_says_what_the_step_hides(uno, tmp_path, capsys):
    described, _, _, path = uno
    out = tmp_path / "fitted.toml"
    code = main(["fit-bias", str(path), "--model", str(described), "--out", str(out)])
    said = capsys.readouterr()
    assert code == 0, said.err
    lines = [line for line in said.out.splitlines() if line.startswith("  noise: ")]
    assert len(lines) == 3, said.out  # one line per axis
    for line in lines:
        assert "the read-out step 14.8 mg (the model's read-out) hides the noise" in line
        assert "to measure it: dither" in line
        assert "a 3.3 V reference" in line and "more ADC bits" in line
    assert (
        "R = 0.00243436 (m/s^2)^2: kept from the base model; sigma_eps = 0.001 m/s^2/sqrt(s) kept from the base "
        "model: the read-out step hides the noise on every axis (x, y, z)" in said.out
    )
    base, fitted = load_model(described), load_model(out)
    assert (fitted.noise.R, fitted.noise.sigma_eps) == (base.noise.R, base.noise.sigma_eps)  # no figure made up


def test_the_bias_lies_within_its_stated_intervals(uno):
    described, real, run, path = uno
    ch = characterise(path, described)
    for j, r in enumerate(ch.axes):
        truth = real.axes[j]
        assert r.quant is not None and r.quant.hidden, r.name
        f = r.fit
        if f.T_identified:
            for k, value in enumerate((truth.c1, truth.c2, truth.T)):
                lo, hi = f.ci95_lr[k]
                assert lo <= value <= hi, (r.name, k, value, f.ci95_lr[k])
        else:  # a constant bias: the mean of the true bias over the record
            lo, hi = f.ci95_lr[1]
            assert lo <= float(np.mean(run.eps[:, j])) <= hi, (r.name, f.ci95_lr[1])
    # without the step's bound the intervals miss the truth: the bound is what makes them hold
    missed = 0
    for j in range(len(ch.axes)):
        plain = fit_bias(run.t, ch.recording.accel[:, j])
        truth = real.axes[j]
        if plain.T_identified:
            missed += not all(
                plain.ci95_lr[k][0] <= v <= plain.ci95_lr[k][1] for k, v in enumerate((truth.c1, truth.c2))
            )
        else:
            missed += not plain.ci95_lr[1][0] <= float(np.mean(run.eps[:, j])) <= plain.ci95_lr[1][1]
    assert missed >= 1


def test_clipping_at_the_adc_rail_is_still_refused(uno, tmp_path, capsys):
    described, _, run, _ = uno
    code = run.code.copy()
    code[30000:30500, 0] = 0  # five seconds at the ADC's bottom rail
    path = tmp_path / "railed.csv"
    np.savetxt(path, np.column_stack([run.t, code]), delimiter=",", header="t,acc_x_counts,acc_y_counts,acc_z_counts",
               comments="", fmt=["%.6f", "%d", "%d", "%d"])  # fmt: skip
    assert main(["fit-bias", str(path), "--model", str(described), "--out", str(tmp_path / "f.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "axis 'x': 500 samples are flagged clipped, the first at sample 30000" in err


def test_samples_in_g_on_the_adcs_grid_are_read_as_quantised(uno, tmp_path, capsys):
    """The same run converted to g by the board and written with 6 decimals, no model given: the step is the
    samples' own grid, and the still part on its few codes is no more clipping than in counts."""
    _, _, run, _ = uno
    path = tmp_path / "still_g.csv"
    g = run.accel / 9.80665
    np.savetxt(path, np.column_stack([run.t, g]), delimiter=",", header="t,acc_x_g,acc_y_g,acc_z_g", comments="",
               fmt=["%.6f", "%.6f", "%.6f", "%.6f"])  # fmt: skip
    code = main(["fit-bias", str(path), "--out", str(tmp_path / "f.toml")])
    said = capsys.readouterr()
    assert code == 0, said.err
    lines = [line for line in said.out.splitlines() if line.startswith("  noise: ")]
    assert len(lines) == 3 and all("14.8 mg (the samples' own grid) hides the noise" in x for x in lines), lines
    # no model of this sensor: R is the rounding plus the most noise the codes allow, which holds the truth
    q = 5 / 1024 / 0.33 * 9.80665
    true_R = (300e-6 * 9.80665) ** 2 * np.pi / 2 * 50 + q**2 / 12  # what init wrote from the datasheet
    assert true_R <= load_model(tmp_path / "f.toml").noise.R <= 1.2 * true_R
    assert "plus the most noise the codes' shares allow (their 95 % upper end): no model of this sensor" in said.out
