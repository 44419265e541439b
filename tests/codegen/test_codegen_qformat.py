"""The one quantizer: round to nearest, then saturate; at +-max and +-0.5 LSB."""

import numpy as np
import pytest

from accelnav.codegen.qformat import QFormat, bits_for, const_format, dequantize, fit, quantize

Q31 = QFormat(32, 31)
Q12_19 = QFormat(32, 19)
Q16_47 = QFormat(64, 47)


@pytest.mark.parametrize(
    "value, fmt, expected",
    [
        (0.0, Q31, 0),
        (0.5 * 2**-31, Q31, 1),  # +0.5 LSB rounds up (ties toward +inf, as the C's rounding shift)
        (-0.5 * 2**-31, Q31, 0),  # -0.5 LSB rounds toward +inf too
        (0.49 * 2**-31, Q31, 0),
        (-0.51 * 2**-31, Q31, -1),
        (1.0, Q31, 2**31 - 1),  # +max saturates
        (1.0 - 2**-31, Q31, 2**31 - 1),
        (-1.0, Q31, -(2**31)),  # -max is exact
        (-2.0, Q31, -(2**31)),
        (1e300, Q16_47, 2**63 - 1),
        (-1e300, Q16_47, -(2**63)),
        (4095.999999, Q12_19, 2**31 - 1),
        (-4096.0, Q12_19, -(2**31)),
    ],
)
def test_quantize_edges(value, fmt, expected):
    assert quantize(value, fmt) == expected
    assert quantize(np.array([value]), fmt)[0] == expected  # the array path agrees


def test_round_trip_within_half_lsb():
    rng = np.random.default_rng(7)
    x = rng.uniform(-4000, 4000, 10000)
    q = quantize(x, Q12_19)
    assert np.max(np.abs(dequantize(q, Q12_19) - x)) <= Q12_19.lsb / 2


def test_formats():
    assert bits_for(1.0) == 1 and bits_for(0.99) == 0 and bits_for(40000) == 16
    assert fit(40000, 64).name == "Q16.47"
    assert fit(0.004, 32).name == "Q-7.38"
    f = const_format(4.8e-7)
    assert 2**30 <= quantize(4.8e-7, f) < 2**31  # per-constant scaling uses the whole word
    with pytest.raises(ValueError):
        quantize(float("nan"), Q31)


def test_compiled_riccati_is_bit_identical_to_python(default_model):
    """The gain recursion's C copy (used for speed) repeats the Python one operation for operation."""
    import numpy as np

    from accelnav.codegen import gains
    from accelnav.model.design import axis_design

    assert gains._riccati_lib() is not None, "a C compiler is on this machine: the compiled path must build"
    key = gains._key(axis_design(default_model, 1))
    valid = np.ones(4000, dtype=bool)
    valid[1500:1530] = False
    for v in (None, valid):
        for keep, rows in ((4000, ()), (1000, (1500, 2222, 3999))):  # streamed: a prefix and rows only
            fast, slow = gains._riccati(key, 4000, v, keep, rows), gains._riccati_py(key, 4000, v, keep, rows)
            for name in ("K", "sigma", "S", "row_K", "row_sigma", "row_S", "kmax", "sigma_max", "max_prior", "max_c"):
                assert np.array_equal(getattr(fast, name), getattr(slow, name)), name
            assert fast.rows == slow.rows and fast.checkpoints == slow.checkpoints
            assert (fast.S_min, fast.S_max) == (slow.S_min, slow.S_max)
            full = gains._riccati_py(key, 4000, v, 4000, ())
            assert np.array_equal(fast.at(2222)[0], full.K[2222]) and np.array_equal(fast.at(-1)[1], full.sigma[-1])
            assert np.array_equal(fast.kmax, np.abs(full.K).max(0))


def test_streamed_bound_is_the_python_bound(default_model):
    """The report's bound over the declared run comes from a C recursion fed by the Riccati sample by
    sample (no per-sample arrays); it repeats codegen.bounds.error_bound operation for operation."""
    import numpy as np

    from accelnav.codegen.bounds import error_bound, error_bound_rows
    from accelnav.codegen.ranges import plan_axis
    from accelnav.model.load import loads_model

    model = loads_model(default_model.text.replace("max_run_s = 3600.0", "max_run_s = 60.0"), source="60s")
    p = plan_axis(model, 1, "covariance")
    rows = [0, 1, 99, 100, 2500, p.n_run - 1]
    want = error_bound(p, p.n_run)[rows]
    assert np.array_equal(error_bound_rows(p, p.n_run, rows), want)
