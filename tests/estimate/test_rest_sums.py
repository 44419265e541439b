"""The rest decision's sums read at a sample (acn_kin_rec, rests._Kinematic): from checkpoints and the rows read
before, the same doubles as acn_kin_sums' whole n + 1 rows, whatever the order of the reads; and the filter's
memory no longer grows with the record by those rows."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.estimate import rests
from accelnav.estimate.fastsmooth import _lib


def _whole(x: np.ndarray, Ts: float, reverse: bool) -> np.ndarray:
    """acn_kin_sums' rows [V, A, W] of every sample, (n + 1, 3 n_axes)."""
    mod = _lib()
    n, n_axes = x.shape
    V, A, W = (np.zeros((n + 1, n_axes)) for _ in range(3))
    buf = mod.ffi.from_buffer
    mod.lib.acn_kin_sums(n, n_axes, buf("double[]", x), reverse, Ts, *(buf("double[]", a) for a in (V, A, W)))
    return np.hstack((V, A, W))


@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize(("n", "n_axes"), [(0, 1), (1, 2), (255, 2), (256, 3), (3000, 2), (1031, 8)])
def test_every_sample_read_in_any_order_is_the_whole_sums_row(n, n_axes, reverse):
    rng = np.random.default_rng(n + n_axes)
    x = rng.normal(0.0, 3.0, (n, n_axes)) * rng.choice([1e-6, 1.0, 1e3], (n, n_axes))  # sums that lose bits
    Ts = 0.01
    want = _whole(x, Ts, reverse)
    kin = rests._Kinematic(x, Ts, np.full(n_axes, 0.01), 0.0025, reverse)
    assert kin.cp.nbytes == (n // rests.SUMS_EVERY + 1) * 3 * n_axes * 8
    mod = _lib()
    out = np.empty(3 * n_axes)
    p = mod.ffi.from_buffer("double[]", out)
    # in order, backwards, at random, the same sample twice, and the kernels' pattern: a row, one far back, on again
    orders = [np.arange(n + 1), np.arange(n, -1, -1), rng.integers(0, n + 1, 3 * n + 5), np.repeat([0, n], 3)]
    orders.append(np.ravel([(k, max(k - 700, 0), min(k + 3, n)) for k in range(0, n + 1, 97)]))
    for order in orders:
        for k in order.tolist():
            mod.lib.acn_kin_sums_at(kin.rec, k, p)
            np.testing.assert_array_equal(out, want[k], err_msg=f"sample {k} of {n}, reverse {reverse}")


def test_the_filter_holds_checkpoints_not_the_record_sums():
    n, n_axes = 200_000, 2
    kin = rests._Kinematic(np.ones((n, n_axes)), 0.01, np.ones(n_axes), 0.0025)
    held = sum(v.nbytes for v in vars(kin).values() if isinstance(v, np.ndarray) and v is not kin.x)
    assert held < 3 * n * n_axes * 8 / 100  # the three sums whole: 9.6 MB; their checkpoints: 37.5 kB


def test_more_axes_than_a_row_holds_are_refused():
    with pytest.raises(ValueError, match="at most 8"):
        rests._Kinematic(np.zeros((10, 9)), 0.01, np.ones(9), 0.0025)


@pytest.mark.parametrize(("field", "value"), [("n_axes", 9), ("n_axes", 0), ("every", 0), ("n", -1)])
def test_the_kernels_refuse_a_record_their_rows_cannot_hold(field, value):
    """The C entry points check the record themselves (a row holds 8 axes; the checkpoints' spacing divides),
    not only the Python that fills it: a caller of the cffi module that skips _Kinematic gets -1, not a write past
    a row or a division by zero."""
    mod = _lib()
    x = np.zeros((300, 9))
    xp = mod.ffi.from_buffer("double[]", x)
    rec = mod.ffi.new("acn_kin_rec *")
    rec.n, rec.n_axes, rec.x, rec.reverse, rec.Ts, rec.every = 300, 2, xp, 0, 0.01, rests.SUMS_EVERY
    cp = np.zeros((300 // rests.SUMS_EVERY + 1, 27))
    assert mod.lib.acn_kin_checkpoints(rec, mod.ffi.from_buffer("double[]", cp)) == 0  # the record as it was made
    setattr(rec, field, value)
    assert mod.lib.acn_kin_checkpoints(rec, mod.ffi.from_buffer("double[]", cp)) == -1


def test_the_backward_pass_refuses_a_record_of_other_axes_or_events_outside_it():
    kin = rests._Kinematic(np.zeros((300, 2)), 0.01, np.ones(2), 0.0025)
    ffi, null = kin.ffi, kin.ffi.NULL  # the calls here read no event value, level or side: NULL for those

    def backward(n_axes, ev_k=(), ev_kind=(), ev_i=(), m=0):
        ev = [
            ffi.from_buffer(t, np.asarray(a, dtype=d)) if len(ev_k) else null
            for t, a, d in (("long[]", ev_k, np.int64), ("int[]", ev_kind, np.int32), ("long[]", ev_i, np.int64))
        ]
        outs = [np.zeros(max(m, 1) * 8 * n_axes) for _ in range(2)]
        acc = np.zeros(max(m, 1), dtype=np.uint8)
        return kin.lib.acn_kin_backward(
            n_axes, kin.s, kin.rec, 0.01, 0.0025, kin._qv, kin._R, m, len(ev_k), *ev, null, null,
            ffi.from_buffer("unsigned char[]", acc), null, null, 0.0, 0.0, 1.0, 0.1,
            *(ffi.from_buffer("double[]", o) for o in outs), null, null,
        )  # fmt: skip

    assert backward(3) == -1  # the record holds 2
    assert backward(2) == 0
    assert backward(2, [301], [1], [0]) == -1  # a fix after the record's end
    assert backward(2, [5], [1], [2]) == -1  # a fix on a third axis
    assert backward(2, [5], [0], [0], m=0) == -1  # a candidate's start with no candidates
    assert backward(2, [9, 5], [1, 1], [0, 0]) == -1  # out of sample order
    kin.rec.n = 200  # the checkpoints were made for 300 samples
    assert backward(2) == -1
    out = np.empty(6)
    assert kin.lib.acn_kin_sums_at(kin.rec, 5, ffi.from_buffer("double[]", out)) == -1


def test_the_window_pass_starts_from_fresh_sums():
    """acn_rest_centres is a whole pass: given a state that has stepped (at >= 0) it would skip those windows'
    sums and flag from a later window's figures, so it refuses."""
    mod = _lib()
    ffi = mod.ffi
    n, w = 50, 5
    x, usable, allow = np.zeros((n, 1)), np.ones(n, dtype=np.uint8), np.ones(1)
    centre = np.zeros(n, dtype=np.uint8)

    def centres(at0):
        state, at = np.zeros(4), np.full(1, at0, dtype=np.int64)
        return mod.lib.acn_rest_centres(
            n, 1, ffi.from_buffer("double[]", x), ffi.from_buffer("unsigned char[]", usable), w,
            ffi.from_buffer("double[]", allow), 1.0, ffi.from_buffer("double[]", state),
            ffi.from_buffer("long[]", at), ffi.from_buffer("unsigned char[]", centre),
        )  # fmt: skip

    assert centres(-1) == 0 and centre[w // 2 : n - w // 2].all()
    assert centres(3) == -1
