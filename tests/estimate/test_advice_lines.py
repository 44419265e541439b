"""Each advice line of a smoothed run's checks (accelnav.estimate.consistency) right on a simulated case, and
absent on one where it would be wrong (issue 31, "checks that act")."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate import zupt
from accelnav.estimate.consistency import HOLDOUT_MIN, NisCheck, nis_check
from accelnav.estimate.kf import position_fix
from accelnav.estimate.pipeline import (
    disagreeing_rests,
    error_rows,
    smooth_checks,
    smooth_run,
    truth_versus_baselines,
)
from accelnav.hil_sim.sim.sensor import simulate

MOVING = 0.5  # m/s: a rest whose true speed reaches this is no rest (the issue's vehicle goal)


def _case(model, scenario, seed, fix_every_s=None, fix_sigma=0.01, duration=60.0):
    """(run arrays, the detector's rests, per-axis fixes or None) of a simulated run."""
    run = simulate(model, scenario, duration, seed).to_arrays()
    p = zupt.resolved(model, zupt.ZuptParams())
    rest = zupt.rest_mask(run["accel"], run["clipped"], model, p)
    fixes = None
    if fix_every_s is not None:
        rng = np.random.default_rng(seed)
        ks = range(0, len(run["t"]), int(round(fix_every_s * model.rate_hz)))
        fixes = [
            [position_fix(k, float(run["r"][k, j] + fix_sigma * rng.standard_normal()), fix_sigma) for k in ks]
            for j in range(len(run["axis_names"]))
        ]
    return run, rest, fixes


def _top_speed(run, a, b) -> float:
    return float(np.linalg.norm(run["u"][a:b], axis=1).max())


def _with_false_rests(run, model, n_false):
    """(N,) mask: the detector's candidates where the body is still (truth) and its ``n_false`` longest quiet
    stretches at speed: rests as an over-eager decision calls them, for the review to re-examine."""
    cand = zupt.intervals(zupt.candidates(run["accel"], run["clipped"], model, zupt.resolved(model, zupt.ZuptParams())))
    true = [(a, b) for a, b in cand if _top_speed(run, a, b) < 0.1 * MOVING]
    false = sorted((iv for iv in cand if _top_speed(run, *iv) > MOVING), key=lambda iv: iv[0] - iv[1])[:n_false]
    mask = np.zeros(len(run["t"]), dtype=bool)
    for a, b in true + false:
        mask[a:b] = True
    return mask


@pytest.fixture(scope="module")
def cart(default_model):
    """A cart pushed about: three quiet rolls (1.2-1.9 m/s) called rests, besides six true ones."""
    run, _, fixes = _case(default_model, "cart_push", 3, fix_every_s=5.0)
    return run, _with_false_rests(run, default_model, 3), fixes


def test_false_rests_are_dropped_against_the_fixes_and_named(cart, default_model):
    run, rest, fixes = cart
    false = [(a, b) for a, b in zupt.intervals(rest) if _top_speed(run, a, b) > MOVING]
    assert len(false) == 3  # the case holds what it is for
    review = disagreeing_rests(run, default_model, rest, fixes=fixes)
    assert sorted((r.start, r.stop) for r in review.dropped) == sorted(false)
    assert all(r.against == "the fixes" and r.chi2 > 10 * r.bound for r in review.dropped)
    for a, b in zupt.intervals(review.kept.any(axis=1)):
        assert _top_speed(run, a, b) < MOVING
    line = review.line()
    assert line.startswith("rests re-examined: 3 of 9 disagree with the rest of the evidence, dropped: ")
    assert line.count("against the fixes") == 3
    # the rests kept do not make the fixes worse: within 1.1x of the fixes alone
    err = {}
    for name, kw in (("fixes", {}), ("kept", {"rest": review.kept}), ("all", {"rest": rest})):
        sm = smooth_run(run, default_model, fixes=fixes, covariances=False, **kw)
        err[name] = float(np.sqrt(np.mean((sm["smooth_x"][:, :, 0].T - run["r"]) ** 2)))
    assert err["kept"] <= 1.1 * err["fixes"] < err["all"], err


def test_without_fixes_the_worst_rests_go_against_the_others_and_only_false_ones(cart, default_model):
    run, rest, _ = cart
    review = disagreeing_rests(run, default_model, rest)
    assert review.dropped and review.complete
    for r in review.dropped:
        assert r.against == "the other rests" and _top_speed(run, r.start, r.stop) > MOVING


def test_true_rests_are_kept_even_where_the_model_is_too_stiff_for_them(default_model):
    run, rest, _ = _case(default_model, "walking", 3)
    review = disagreeing_rests(run, default_model, rest)
    assert review.tested > 50 and review.dropped == () and not review.said
    sm = smooth_run(run, default_model, rest=review.kept)
    checks = smooth_checks(sm, default_model, run, review=review, rest=review.kept)
    (rests,) = checks.nis
    assert rests.verdict == "stiff"  # all rests alike: a model too stiff for them, or rests not quite still
    assert checks.lines() == [rests.line()]
    assert "only fixes can tell" in rests.line() and "--tune" not in rests.line() and not checks.tune_helps


def test_true_rests_with_fixes_are_kept(default_model):
    run, rest, fixes = _case(default_model, "stop_and_go", 3, fix_every_s=5.0)
    review = disagreeing_rests(run, default_model, rest, fixes=fixes)
    assert review.tested >= 4 and review.dropped == () and not review.said


@pytest.mark.parametrize(("verdict", "mean"), [("stiff", 9.0), ("loose", 0.1)])
def test_try_tune_only_for_the_fixes_and_never_after_tuning(verdict, mean):
    n = 40
    base = nis_check("fixes", np.full(n, 1.0))
    fixes = NisCheck("fixes", n, mean, base.low, base.high)
    rests = NisCheck("rests", n, mean, base.low, base.high)
    assert fixes.verdict == rests.verdict == verdict
    assert fixes.line().endswith("try --tune")
    assert "--tune" not in fixes.line(tuned=True) and "tuned model" in fixes.line(tuned=True)
    assert "--tune" not in rests.line() and "only fixes can tell" in rests.line()


@pytest.fixture(scope="module")
def stiff_vehicle():
    from support.vehicle_fixes import vehicle_case

    return vehicle_case()


def test_held_out_judgement_needs_enough_fixes(stiff_vehicle):
    run, shipped, _, fixes = stiff_vehicle
    sm = smooth_run(run, shipped, fixes=fixes)
    c = smooth_checks(sm, shipped, run, fixes)
    assert c.holdout.n >= HOLDOUT_MIN and c.tune_helps
    assert c.holdout.worse_than() and any(x.startswith("the smoother misses the held-out") for x in c.lines())
    assert c.lines()[-1].endswith("try --tune")
    # three fixes per axis: one held out on each, which can show nothing; the same model, the same misses
    few = [f[6:9] for f in fixes]
    sm = smooth_run(run, shipped, fixes=few)
    c = smooth_checks(sm, shipped, run, few)
    assert c.holdout.n == 2 < HOLDOUT_MIN and c.holdout.worse_than() == []
    assert c.holdout.rms["smoother"] > c.holdout.rms["fix interpolation"]  # which the rms alone called a loss
    held = [x for x in c.lines() if x.startswith("held-out")]
    assert held == [
        "held-out fixes (every other one left out): 2 predicted, too few to judge the smoother against fixes "
        f"alone: {HOLDOUT_MIN} at least (losing at all of fewer has a chance above 5 %)"
    ]
    assert not any("misses the held-out" in x for x in c.lines())


def test_held_out_loss_by_one_far_fix_is_not_a_verdict(stiff_vehicle):
    """The rms alone would call it: one fix far off; the sign test does not."""
    from accelnav.estimate.pipeline import Holdout

    n = 12
    base = np.full(n, 1.0)
    smoother = np.full(n, 0.5)
    smoother[3] = 170.0
    h = Holdout(n, {"smoother": 49.0, "fix interpolation": 1.0, "fix-to-fix integration": 1.0},
                {"smoother": smoother, "fix interpolation": base, "fix-to-fix integration": base})  # fmt: skip
    assert h.losses("fix interpolation") == 1 and h.worse_than() == []


def test_truth_line_advises_tune_only_when_tuning_helps(stiff_vehicle):
    run, shipped, _, fixes = stiff_vehicle
    sm = smooth_run(run, shipped, fixes=fixes)
    from accelnav.estimate.pipeline import fix_baselines

    rows = error_rows(run["axis_names"], run["r"], {"smoother": sm["smooth_x"][:, :, 0], **fix_baselines(sm, shipped)})
    assert truth_versus_baselines(rows, True).endswith("does not fit this recording: try --tune")
    assert truth_versus_baselines(rows, False).endswith("does not fit this recording")


def test_a_run_that_nothing_anchors_says_so(default_model):
    run, rest, fixes = _case(default_model, "highway", 3, fix_every_s=1.0, fix_sigma=1.0)
    assert not rest.any()  # a cruise: no still start, no stop
    sm = smooth_run(run, default_model, rest=rest)
    c = smooth_checks(sm, default_model, run, rest=rest)
    sd = float(sm["smooth_sd"][:, -1, 0].max())
    assert sd > 10 and c.no_anchor is not None and c.no_anchor.sd == sd
    head = "no rest applied and no fixes: nothing anchors the position, whose sd reaches"
    assert c.lines()[-1].startswith(f"{head} {sd:.3g} m")
    assert "a still start of 1 s, position fixes (--fixes) or a rest file (--zupt FILE)" in c.lines()[-1]
    # with fixes, or with rests applied, or without rests asked for: not said
    sm = smooth_run(run, default_model, rest=rest, fixes=fixes)
    assert smooth_checks(sm, default_model, run, fixes, rest=rest).no_anchor is None
    assert smooth_checks(smooth_run(run, default_model), default_model, run).no_anchor is None
    walk, wrest, _ = _case(default_model, "walking", 3)
    sm = smooth_run(walk, default_model, rest=wrest)
    assert smooth_checks(sm, default_model, walk, rest=wrest).no_anchor is None


@pytest.mark.parametrize("scenario", ["highway_gnss", "town_drive", "hand_box"])
def test_issue_31_cases_with_fixes_lose_their_rests_at_speed_and_no_accuracy(default_model, scenario):
    """The rest-cases scenarios with the fixes a user has there, through the rest stage of --zupt auto (the
    decision with the fixes, then the review): every rest the decision calls while the body moves is dropped
    against the fixes, none is left at speed, and --zupt auto ends within 1.1x of the fixes alone."""
    from accelnav.estimate import engine
    from accelnav.estimate.pipeline import fixes_per_axis

    run = simulate(default_model, scenario, 120.0, 1).to_arrays()
    fixes = fixes_per_axis({"t": run["t"], "axis_names": run["axis_names"], "fixes": run["sim_fixes"]})
    p = zupt.resolved(default_model, zupt.ZuptParams())
    decided = zupt.rest_mask(run["accel"], run["clipped"], default_model, p, fixes)
    stage = engine.rest_stage(default_model, run, engine.Rests(p, detect=True), fixes=fixes)
    if any(_top_speed(run, a, b) > MOVING for a, b in zupt.intervals(decided)):  # the decision's mistake
        review = stage.review
        assert review.said and review.dropped and all(r.against == "the fixes" for r in review.dropped)
    for a, b in zupt.intervals(stage.mask):
        assert _top_speed(run, a, b) < MOVING
    err = {}
    for name, kw in (("fixes", {}), ("kept", {"rest": stage.mask, "zupt_params": p})):
        sm = smooth_run(run, default_model, fixes=fixes, covariances=False, **kw)
        err[name] = float(np.sqrt(np.mean((sm["smooth_x"][:, :, 0].T - run["r"]) ** 2)))
        if name == "kept" and stage.mask.any():  # a still start left alone tests nothing: no line from it
            lines = smooth_checks(sm, default_model, run, review=stage.review, rest=stage.mask, zupt_params=p).nis
            assert not any(c.kind == "rests" and c.verdict == "loose" for c in lines)
    assert err["kept"] <= 1.1 * err["fixes"], err


def test_without_fixes_a_still_start_outvotes_the_stops_at_speed(default_model):
    """town_drive without its fixes: the still start (the filter's u = 0 at the start confirms it) and two quiet
    spells at cruise; both spells go, the start stays, and what is left is said to be anchored by nothing."""
    run, _, _ = _case(default_model, "town_drive", 1, duration=120.0)
    rest = _with_false_rests(run, default_model, 2)
    iv = zupt.intervals(rest)
    assert iv[0][0] == 0 and sum(_top_speed(run, a, b) > MOVING for a, b in iv) == 2
    review = disagreeing_rests(run, default_model, rest)
    assert len(review.dropped) == 2 and all(r.against == "the other rests" for r in review.dropped)
    assert zupt.intervals(review.kept.any(axis=1)) == [iv[0]]
    sm = smooth_run(run, default_model, rest=review.kept)
    c = smooth_checks(sm, default_model, run, review=review, rest=review.kept)
    end = run["t"][iv[0][1] - 1]
    assert c.lines()[0] == review.line() and c.lines()[-1].startswith(f"no rest applied after {end:.3g} s and no fixes")


def test_two_rests_that_disagree_are_said_undecided(cart, default_model):
    """Two rests, neither at the start: one true, one at speed; nothing says which is wrong, and that is said."""
    run, rest, _ = cart
    iv = [(a, b) for a, b in zupt.intervals(rest) if a > 0]
    false = [(a, b) for a, b in iv if _top_speed(run, a, b) > MOVING][-1]
    true = next((a, b) for a, b in iv if _top_speed(run, a, b) < MOVING and a > false[0])
    two = np.zeros(len(rest), dtype=bool)
    for a, b in (true, false):
        two[a:b] = True
    review = disagreeing_rests(run, default_model, two)
    assert review.undecided and review.dropped == () and review.said
    assert review.line() == (
        "rests re-examined: 0 of 2 disagree with the rest of the evidence, dropped; the rests left disagree, but two "
        "cannot say which of them is wrong (fixes could)"
    )


def test_the_review_says_when_its_budget_ran_out(cart, default_model, monkeypatch):
    from accelnav.estimate import consistency

    run, rest, _ = cart
    monkeypatch.setattr(consistency, "REVIEW_SMOOTHINGS", 1)
    review = disagreeing_rests(run, default_model, rest)
    assert not review.complete and review.said and review.dropped == ()
    assert review.line().endswith("; stopped at its budget (1 smoothings) with suspects left")
    monkeypatch.undo()
    assert disagreeing_rests(run, default_model, rest).complete


def test_the_reviews_last_smoothing_is_the_one_with_the_rests_it_kept(cart, default_model):
    """Rests dropped one at a time against the others: the smoothing the review hands on (for the one-chunk
    output) is made with the rests left after the last drop, never one that still held a dropped rest."""
    run, rest, _ = cart
    review = disagreeing_rests(run, default_model, rest)
    assert review.dropped and review.smoothed is not None
    ref = smooth_run(run, default_model, rest=review.kept, covariances=False)
    for key in ("smooth_x", "smooth_sd", "zupt", "zupt_nis"):
        np.testing.assert_array_equal(review.smoothed[key], ref[key], err_msg=key)
