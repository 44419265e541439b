"""rests.Clock: the record's times the decision's words name, the very doubles np.arange(n) * Ts gives (the words
print them: "the rest at 12.34 s"), without an array of the record's length."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate.rests import Clock


@pytest.mark.parametrize("Ts", [0.01, 1 / 100, 1 / 3, 0.0025])
def test_the_clock_gives_aranges_doubles(Ts):
    n = 200_003
    t, c = np.arange(n) * Ts, Clock(n, Ts)
    ks = np.r_[0, 1, np.random.default_rng(2).integers(0, n, 500), n - 1, -1, -n]
    np.testing.assert_array_equal(c[ks].view(np.int64), t[ks].view(np.int64))
    for k in ks[:20].tolist():
        assert c[k] == t[k] and type(c[k]) is type(t[k]) and f"{c[k]:.2f}" == f"{t[k]:.2f}"
    assert len(c) == n
    for bad in (n, -n - 1):
        with pytest.raises(IndexError):
            c[bad]
