"""accelnav tune: maximum-likelihood noise figures recover simulated ones and leave a well-specified model alone.

Data come from the filter's own process model (white jerk of intensity sigma_n, bias walk sigma_eps, white
measurement noise R), so the true figures are defined; position fixes every second make the bias walk
identifiable. Stated tolerances (60 s at 100 Hz, one axis): sigma_n within 10 %, R within 5 %, sigma_eps
within a factor 1.6, and each truth inside the 95 % interval.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize
from support.tune_cases import TRUE, one_axis_model, process

from accelnav.cli import main
from accelnav.estimate.tune import all_figures, loglik, tune, with_figures
from accelnav.model.edit import dump_model, revalidate, with_noise
from accelnav.model.load import DEFAULT_MODEL, load_model


@pytest.mark.parametrize("seed", [1, 2])
def test_recovers_simulated_noise_figures(seed):
    truth = one_axis_model(**TRUE)
    z, valid, extras = process(truth, 6000, seed)
    start = with_noise(truth, sigma_n=3.0, sigma_eps=0.05, R=0.05)
    r = tune(start, z, valid, extras)
    assert r.adopted and r.p_value < 1e-6
    assert r.ll_estimate > r.ll_start
    assert r.estimate["sigma_n"] == pytest.approx(TRUE["sigma_n"], rel=0.10)
    assert r.estimate["R"] == pytest.approx(TRUE["R"], rel=0.05)
    assert 1 / 1.6 < r.estimate["sigma_eps"] / TRUE["sigma_eps"] < 1.6
    for f, v in TRUE.items():
        lo, hi = r.ci95[f]
        assert lo <= v <= hi, (f, lo, v, hi)
        assert r.identified(f)


def test_well_specified_model_is_not_made_worse():
    truth = one_axis_model(**TRUE)
    adopted = 0
    for seed in (11, 12, 13):
        z, valid, extras = process(truth, 4000, seed)
        r = tune(truth, z, valid, extras)
        adopted += r.adopted
        # held-out data: the written figures explain new data at least about as well as the truth does
        z2, v2, e2 = process(truth, 4000, seed + 100)
        chosen = with_figures(truth, r.chosen)
        assert loglik(chosen, z2, v2, e2) >= loglik(truth, z2, v2, e2) - 2.0
        if not r.adopted:
            assert r.chosen == all_figures(truth)
    assert adopted <= 1  # a 5 % test: three well-specified runs adopt a change at most once


def test_recovers_the_constant_bias_c2():
    truth = with_figures(one_axis_model(**TRUE), {"c2.x": 0.3})
    z, valid, extras = process(truth, 4000, 21)
    start = with_figures(truth, {"c2.x": 0.0, "R": 0.03})
    r = tune(start, z, valid, extras, figures=("R", "c2"))
    assert r.adopted and r.figures == ("R", "c2.x")
    lo, hi = r.ci95["c2.x"]
    assert lo <= 0.3 <= hi and hi - lo < 0.2, (lo, hi)
    assert r.identified("c2.x")


def test_sigma_eps_without_aids_is_reported_not_identified():
    """Without rests or fixes z = a + eps + v sees two random walks (the motion's, sigma_n, and the bias's,
    sigma_eps) and only about their sum of squares is identified: neither figure on its own."""
    truth = one_axis_model(**TRUE)
    z, valid, _ = process(truth, 3000, 5)
    r = tune(with_noise(truth, sigma_n=2.0), z, valid, [[]], figures=("sigma_n", "sigma_eps"))
    assert not r.identified("sigma_eps")
    # a smaller motion walk with a larger bias walk fits as well: sigma_n's profile is open below
    assert r.ends["sigma_n"][0] == "open" and not r.identified("sigma_n")
    assert "open below" in r.why_not_identified("sigma_n")
    # a smaller budget holds (but for the Hessian's and the last step's few), and an end it cannot reach is said
    small = tune(with_noise(truth, sigma_n=2.0), z, valid, [[]], figures=("sigma_n", "sigma_eps"), max_evaluations=300)
    assert small.evaluations <= 300 + 30
    assert small.why_not_identified("sigma_n") in (
        "profile not closed within the evaluation budget",
        "profile open below within the search range",
    )
    # with the bias walk held, sigma_n is identified and its interval holds the truth
    r = tune(with_noise(truth, sigma_n=2.0), z, valid, [[]], figures=("sigma_n", "R"))
    assert r.identified("sigma_n") and r.identified("R")
    assert r.ci95["sigma_n"][0] <= TRUE["sigma_n"] <= r.ci95["sigma_n"][1]


def test_interval_ends_are_where_the_profile_likelihood_drops_by_1_92():
    """Each end of a noise figure's interval: re-optimising the other figures there (an independent, tighter
    search) leaves -ln L 1.92 above its minimum (chi-square 1 dof, 95 %)."""
    truth = one_axis_model(**TRUE)
    z, valid, extras = process(truth, 2000, 3)
    r = tune(with_noise(truth, sigma_n=3.0, sigma_eps=0.05, R=0.05), z, valid, extras)
    f0 = -r.ll_estimate

    def nll(v):
        return -loglik(with_figures(truth, v, check=False), z, valid, extras)

    for f in ("sigma_n", "sigma_eps", "R"):
        assert r.ends[f] == ("closed", "closed"), (f, r.ends[f])
        lo, hi = r.ci95[f]
        assert lo < r.estimate[f] < hi
        others = [g for g in ("sigma_n", "sigma_eps", "R") if g != f]
        for end in (lo, hi):

            def inner(x, end=end, others=others, f=f):
                return nll({f: end, **{g: math.exp(v) for g, v in zip(others, x, strict=True)}})

            x0 = [math.log(r.estimate[g]) for g in others]
            best = optimize.minimize(inner, x0, method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-6})
            assert best.fun - f0 == pytest.approx(1.92, abs=0.06), (f, end, best.fun - f0)


def test_interval_coverage_over_seeds():
    """A cheap coverage check (8 seeds, 20 s runs, 24 intervals). A calibrated 95 % interval misses 4 or more
    of 24 with probability 3 %. The longer check (100 seeds) is in the README."""
    truth = one_axis_model(**TRUE)
    covered = 0
    for seed in range(8):
        z, valid, extras = process(truth, 2000, seed)
        r = tune(with_noise(truth, sigma_n=3.0, sigma_eps=0.05, R=0.05), z, valid, extras)
        for f, v in TRUE.items():
            lo, hi = r.ci95[f]
            covered += bool(lo <= v <= hi)
    assert covered >= 21, covered


def test_cli_on_a_simulated_stop_and_go(tmp_path, capsys):
    run = tmp_path / "sg.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "30", "--seed", "3", "--out", str(run)]) == 0
    start = tmp_path / "start.toml"
    start.write_text(dump_model(revalidate(with_noise(load_model(DEFAULT_MODEL), sigma_n=5.0, R=0.05))))
    out = tmp_path / "tuned.toml"
    capsys.readouterr()
    assert main(["tune", str(run), "--model", str(start), "--zupt", "auto", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| sigma_n |" in text and "significantly better" in text and "written" in text
    m = load_model(out)
    # the simulator's noise: 8.9 mg analog + the ADC's rounding; R is far below the bad start's 0.05
    assert 0.005 < m.noise.R < 0.025 and m.noise.sigma_n < 5.0
    assert out.read_text().startswith("# accelnav model written by accelnav tune\n")
    # with sigma_n held at the bad 5, the likelihood drives R to its search bound: said, not called identified
    assert (
        main(["tune", str(run), "--model", str(start), "--zupt", "auto", "--figures", "R,c2", "--out", str(out)]) == 0
    )
    text = capsys.readouterr().out
    assert "| R | 0.05 |" in text and "NO (at the search bound)" in text and "| c2.y |" in text


def test_cli_refusals(tmp_path, capsys):
    run = tmp_path / "s.npz"
    assert main(["sim", "--scenario", "stationary", "--duration", "5", "--out", str(run)]) == 0
    capsys.readouterr()
    assert main(["tune", str(run), "--figures", "sigma_x", "--out", str(tmp_path / "o.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--figures: sigma_x unknown" in err and "\n" not in err


def test_cli_takes_a_csv_recording_and_a_zupt_file(tmp_path, capsys):
    """tune reads recordings through the same checked reader as filter and smooth, and ZUPT files in smooth's form."""
    run = tmp_path / "sg.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "30", "--seed", "3", "--out", str(run)]) == 0
    d = np.load(run)
    csv = tmp_path / "rec.csv"
    rows = np.column_stack([d["t"], d["accel"]])
    np.savetxt(csv, rows, delimiter=",", header="t,ax_m_s2,ay_m_s2", comments="", fmt="%.9g")
    rest = np.all(d["u"] == 0, axis=1).astype(int)
    zfile = tmp_path / "rest.csv"
    np.savetxt(zfile, rest, header="rest", comments="", fmt="%d")
    out = tmp_path / "tuned.toml"
    capsys.readouterr()
    args = ["tune", str(csv), "--time-column", "t", "--axis", "ax_m_s2", "--axis", "ay_m_s2", "--unit", "m/s^2"]
    assert main([*args, "--zupt", str(zfile), "--figures", "R", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    n_rest = int(rest.sum())
    assert f"zero-velocity updates per axis {n_rest}, {n_rest}" in text
    assert 0.005 < load_model(out).noise.R < 0.025
    # a rate that is not the model's is refused in one line, as for smooth
    assert main([*args[:2], "--rate", "50", "--axis", "ax_m_s2", "--out", str(out)]) == 2
    assert "\n" not in capsys.readouterr().err.strip()
