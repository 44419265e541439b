"""accelnav.estimate.engine: the plan says which path and why; a stage's extra smoother pass is bounded and
gives the numbers of the whole-array smoother."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import assert_rel_close

from accelnav.errors import UserError
from accelnav.estimate import chunked, engine
from accelnav.estimate.kf import Aids
from accelnav.estimate.pipeline import smooth_run
from accelnav.model.load import load_model


def _run(model, n, seed=4):
    rng = np.random.default_rng(seed)
    accel = np.cumsum(rng.normal(0, 0.05, (n, len(model.axes))), axis=0)
    t = np.arange(n) / model.rate_hz
    return {"t": t, "axis_names": np.array([a.name for a in model.axes]), "accel": accel,
            "clipped": np.zeros(accel.shape, dtype=bool)}  # fmt: skip


def test_the_plan_cuts_by_size_and_says_why():
    small, big = 10**3, 10**7
    per = chunked.whole_bytes(1, 2)
    p = engine.plan(small, 2, engine.Job(budget=per * small))
    assert (p.whole, p.chunks) == (False, 1) and "one chunk" in p.why
    p = engine.plan(big, 2, engine.Job(budget=per * small))
    assert not p.whole and p.chunks > 1 and f"{p.chunks} chunks of {p.chunk} samples" in p.why
    p = engine.plan(small, 2, engine.Job(budget=per * small, fixes=[[], []]))
    assert p.whole and "consistency checks" in p.why  # within the budget the aids' checks need every sample
    p = engine.plan(small, 2, engine.Job(budget=per * small, covariances=True))
    assert p.whole and "--covariances" in p.why
    # over the budget the covariances are written chunk by chunk, in smaller chunks (their buffers count)
    p = engine.plan(big, 2, engine.Job(budget=per * small, covariances=True))
    assert not p.whole and p.chunk == chunked.chunk_samples(2, min(chunked.BUDGET, per * small), covariances=True)
    assert p.chunk < engine.plan(big, 2, engine.Job(budget=per * small)).chunk
    # --tune and --plots: one chunk within the budget, chunked over it (the likelihood and the envelope streamed)
    for job in (engine.Job(budget=per * small, tune=engine.Tune()), engine.Job(budget=per * small, envelope=True)):
        assert engine.plan(small, 2, job).whole
        p = engine.plan(big, 2, job)
        assert not p.whole and p.chunks > 1
    # what still needs every sample in memory is refused over the budget, in one line that names it
    with pytest.raises(UserError, match="over the memory budget.*arrays returned in memory"):
        engine.plan(big, 2, engine.Job(budget=per * small), to_file=False)


def test_a_stages_extra_smoother_pass_gives_the_whole_array_numbers(tmp_path):
    model = load_model()
    n = 3000
    arrays = _run(model, n)
    rest = np.zeros(n, dtype=bool)
    rest[1000:1100] = rest[2500:2600] = True
    at = np.array([5, 999, 1050, 2000, 2999, 1050])
    extras = [Aids.zero_velocity(np.flatnonzero(rest), 0.02) for _ in model.axes]
    source = engine.Source.of(arrays)
    got = engine.smoother_pass(model, source, extras, at, workdir=tmp_path, budget=20_000)  # many chunks
    ref = smooth_run(arrays, model, rest=rest, covariances=False)
    for j in range(len(model.axes)):
        sd = ref["smooth_sd"][j, at, 1]
        assert_rel_close(got[j, :, 0], ref["smooth_x"][j, at, 1], sd, 1e-12, f"u axis {j}")
        assert_rel_close(got[j, :, 1], sd, 0.0, 1e-12, f"sd_u axis {j}")
    assert list(tmp_path.iterdir()) == []  # its temporary output removed


_OUTPUTS = ("filt_x", "filt_sd", "smooth_x", "smooth_sd", "zupt", "fixes", "fix_nis", "zupt_nis")


@pytest.mark.parametrize("with_fixes", [False, True])
def test_detected_rests_one_chunk_output_is_a_smoothing_with_the_rests_kept(default_model, with_fixes):
    """--zupt auto on one chunk takes the rests' review's last smoothing as its output (not made twice): it must
    be the smoothing with the rests the stage kept, the fixes and the model, as a fresh one gives it."""
    from accelnav.estimate import zupt
    from accelnav.estimate.pipeline import fixes_per_axis
    from accelnav.hil_sim.sim.sensor import simulate

    run = simulate(default_model, "hand_box", 120.0, 1).to_arrays()
    fixes = fixes_per_axis({"t": run["t"], "axis_names": run["axis_names"], "fixes": run["sim_fixes"]})
    fixes = fixes if with_fixes else None
    p = zupt.resolved(default_model, zupt.ZuptParams())
    job = engine.Job(stages=("filt", "smooth"), fixes=fixes, rests=engine.Rests(p, detect=True))
    got = engine.run(default_model, engine.Source.of(run), job)
    stage = got.rests
    assert got.plan.whole and stage.review is not None and stage.mask.any()  # the review ran, rests were kept
    assert stage.smoothed is None and stage.review.smoothed is None  # not held beyond the run
    # the case holds rests the review drops (against the fixes, else one at a time against the other rests): a
    # smoothing that still held one would differ
    assert stage.review.dropped
    ref = smooth_run(run, default_model, fixes=fixes, rest=stage.mask, zupt_params=p, covariances=False)
    for key in _OUTPUTS:
        np.testing.assert_array_equal(got.arrays[key], ref[key], err_msg=key)


def test_the_rest_decision_is_refused_over_the_budget_in_one_line():
    """--zupt auto reads every sample into memory for its decision (engine.rest_bytes): a run whose decision needs
    more than the budget is refused by the plan, before anything is read; within it, or given rests, it is not."""
    auto = engine.Job(rests=engine.Rests(detect=True))
    n, need = 10**7, engine.rest_bytes(10**7, 2)
    assert need == n * (engine.REST_SAMPLE_BYTES + 2 * engine.REST_AXIS_BYTES)
    with pytest.raises(UserError) as exc:
        engine.plan(n, 2, replace(auto, budget=need - 1))
    assert "rest decision of --zupt auto" in str(exc.value) and "\n" not in str(exc.value)
    assert not engine.plan(n, 2, replace(auto, budget=need)).whole  # within it: chunked, the decision whole
    for job in (engine.Job(budget=need // 10, rests=engine.Rests(mask=np.zeros(n, dtype=bool))),
                replace(auto, budget=need // 10, stages=("filt",))):  # fmt: skip
        engine.plan(n, 2, job)  # given rests stream; the filter decides no rests
    small = engine.REST_FLOOR // engine.rest_bytes(1, 2)  # under the process' own floor: a tiny budget cuts chunks
    assert engine.plan(small, 2, replace(auto, budget=20_000)).chunks > 1
    with pytest.raises(UserError, match="rest decision"):
        engine.plan(small + 1, 2, replace(auto, budget=20_000))


def test_candidate_times_are_kept_as_the_chunks_are_read():
    """A chunked --zupt auto run names its candidates' times from the chunks it reads (engine._Times), not from one
    more pass over the input: the same t as Source.times_at, and that pass still answers what was not read."""
    from types import SimpleNamespace

    n = 100
    t = 0.5 + np.arange(n) / 7.0
    decisions = [SimpleNamespace(start=a, stop=b, accepted=True) for a, b in ((3, 9), (20, 21), (40, 100))]
    rest = engine.RestOutcome(None, None, None, decisions=decisions, detected=True)
    asked = []

    def times_at(k):
        asked.append(np.asarray(k))
        return t[k]

    times = engine._Times(rest, n)
    at = np.array([3, 20, 40, 8, 20, 99])
    for s in range(0, 60, 30):  # samples 60.. not read yet: the pass answers
        times.read(s, t[s : s + 30])
    np.testing.assert_array_equal(times.at(at, times_at), t[at])
    assert len(asked) == 1
    times.read(60, t[60:])
    np.testing.assert_array_equal(times.at(at, times_at), t[at])
    np.testing.assert_array_equal(times.at(np.array([5]), times_at), t[[5]])  # not a candidate's end: asked
    assert len(asked) == 2


def test_a_chunks_updates_are_the_whole_runs_with_their_variance_shared(default_model):
    """_AxisAids.between's updates of detected rests (one sigma for all, RestSpans.updates' 0-d): the whole run's
    axis_aids, a chunk at a time, their R one read-only array for all chunks, made again for another sigma."""
    from accelnav.estimate import zupt

    n = 3000
    mask = np.zeros(n, dtype=bool)
    mask[100:900] = mask[1500:2950] = True
    spans = zupt.RestSpans.of_mask(mask)
    fill = engine._UpdateFill()
    for sigma in (0.02, 0.03):
        p = zupt.ZuptParams(sigma=sigma)
        want = zupt.axis_aids(mask, None, default_model, p)
        aids = engine._AxisAids(default_model, 0, Aids.of([]), spans, p, fill=fill)
        pieces = [aids.between(s, min(s + 700, n)) for s in range(0, n, 700)]
        np.testing.assert_array_equal(np.concatenate([q.ex.k for q in pieces]), want.k)
        np.testing.assert_array_equal(np.concatenate([q.ex.R for q in pieces]), want.R)
        assert np.all(np.concatenate([q.ex.R for q in pieces]) == sigma**2)
        assert all(not q.ex.R.flags.writeable for q in pieces)  # shared: no chunk may write it
        assert np.shares_memory(pieces[4].ex.R, pieces[3].ex.R)  # 150 updates after 700: the grown array's first rows
