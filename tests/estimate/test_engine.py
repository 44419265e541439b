"""accelnav.estimate.engine: the plan says which path and why; a stage's extra smoother pass is bounded and
gives the numbers of the whole-array smoother."""

from __future__ import annotations

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
    with pytest.raises(UserError, match="over the memory budget.*--covariances"):
        engine.plan(big, 2, engine.Job(budget=per * small, covariances=True))


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
