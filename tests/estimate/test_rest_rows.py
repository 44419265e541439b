"""The run file's candidate rows (engine.RestOutcome.candidate_rows): [start_s, end_s, accepted] per candidate, a
candidate accepted only where the rest mask still holds some of its samples (the review may have dropped it)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from accelnav.estimate.engine import RestOutcome


def test_a_candidate_is_accepted_where_the_mask_still_holds_it():
    t = np.arange(20) * 0.5
    mask = np.zeros(20, dtype=bool)
    mask[2:5] = True  # the first candidate's rest, kept
    mask[15] = True  # one sample of the last candidate's
    # the detector's spans (in order, apart, touching, to the end) and spans that overlap
    ordered = [(2, 5, True), (7, 10, True), (10, 12, False), (12, 13, True), (14, 20, True)]
    for spans, accepted in ((ordered, [1, 0, 0, 0, 1]), (ordered[:4], [1, 0, 0, 0]),
                            ([*ordered, (19, 20, True)], [1, 0, 0, 0, 1, 0])):  # fmt: skip
        decisions = [SimpleNamespace(start=a, stop=b, accepted=ok) for a, b, ok in spans]
        for m in (mask, np.column_stack((mask, np.zeros(20, dtype=bool)))):  # (N,) or (N, n_axes)
            rows = RestOutcome(m, None, None, decisions).candidate_rows(t)
            want = [[t[a], t[b - 1], float(ok and m[a:b].any())] for a, b, ok in spans]
            np.testing.assert_array_equal(rows, np.array(want))
            np.testing.assert_array_equal(rows[:, 2], accepted)  # a rest dropped by the review is not accepted
    assert RestOutcome(mask, None, None, []).candidate_rows(t).shape == (0, 3)
