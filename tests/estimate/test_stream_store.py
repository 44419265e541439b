"""The chunked smoother's store in memory or on disk (store_memory): the same bytes out; and the filter alone."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate import chunked
from accelnav.estimate.kf import position_fix
from accelnav.model.load import load_model


def _data(model, n):
    rng = np.random.default_rng(8)
    accel = np.cumsum(rng.normal(0, 0.05, (n, len(model.axes))), axis=0)
    clipped = np.zeros(accel.shape, dtype=bool)
    clipped[n // 2, 1] = True
    return np.arange(n) / model.rate_hz, accel, clipped


@pytest.mark.parametrize("aided", [False, True], ids=["plain", "a fix on axis 0"])
def test_store_in_memory_and_on_disk_give_the_same_file(tmp_path, aided):
    """Axis 1 leaves the lean store at a clipped sample; with a fix, axis 0 takes the general path's store."""
    model = load_model()
    n = 3000
    read = chunked.array_reader(*_data(model, n))
    extras = [[position_fix(2000, 1.0, 0.1)], []] if aided else None
    kw = dict(chunk=701, extras=extras)
    a = chunked.smooth_bounded(model, n, read, tmp_path / "mem.npz", store_memory=1 << 30, **kw)
    b = chunked.smooth_bounded(model, n, read, tmp_path / "disk.npz", **kw)
    assert a["store_in_memory"] and not b["store_in_memory"]
    assert (tmp_path / "mem.npz").read_bytes() == (tmp_path / "disk.npz").read_bytes()


def test_the_filter_alone_writes_the_smoothers_filter_states(tmp_path):
    model = load_model()
    n = 2000
    read = chunked.array_reader(*_data(model, n))
    chunked.smooth_bounded(model, n, read, tmp_path / "both.npz", chunk=333)
    chunked.smooth_bounded(model, n, read, tmp_path / "f.npz", chunk=333, stages=("filt",))
    with np.load(tmp_path / "both.npz") as both, np.load(tmp_path / "f.npz") as f:
        assert "smooth_x" not in f and not list((tmp_path).glob(".accelnav-*"))
        for key in ("t", "accel", "clipped", "filt_x", "filt_sd"):
            assert np.array_equal(f[key], both[key])


@pytest.mark.parametrize(
    ("budget", "in_memory"),
    [
        (2 * 8 * chunked.LROW * 3000 + 8 * chunked.ROW * (3000 - 1402), True),
        (2 * 8 * chunked.LROW * 3000 + 1000, False),
    ],
    ids=["lean and the late full store in memory", "lean in memory, the full store on disk"],
)
def test_a_store_is_counted_by_the_rows_it_will_hold(tmp_path, budget, in_memory):
    """The lean stores (chunked.LROW doubles a sample) take the budget first; axis 1's full store opens at its clipped
    sample (n/2, in the chunk from 1402) with rows for the samples left only, in memory if they fit, else on
    disk: the same file."""
    model = load_model()
    n = 3000
    read = chunked.array_reader(*_data(model, n))
    a = chunked.smooth_bounded(model, n, read, tmp_path / "mixed.npz", chunk=701, store_memory=budget)
    b = chunked.smooth_bounded(model, n, read, tmp_path / "disk.npz", chunk=701)
    assert a["store_in_memory"] is in_memory and not b["store_in_memory"]
    assert (tmp_path / "mixed.npz").read_bytes() == (tmp_path / "disk.npz").read_bytes()
