"""Issue 32: the rest detector's record and window pass in C (acn_rest_prepare; acn_rest_centres, acn_rest_span) give
the very doubles the numpy they replaced gave, so the candidates and every decision on them are unchanged. The numpy is
tests/support/zupt_oracle.py's (main's detector before issue 24; its record and window pass are main's to the
bit, and tests/estimate/test_zupt_arrays.py holds the present candidates to its). On the bench's tiled
stop-and-go, simulated scenarios, random records with NaN, infinite and clipped samples and gaps of unusable
rows, windows at the record's ends, records about a window long, and a window exactly on the var_k bound."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MODELS
from support import zupt_oracle as ref

from accelnav.estimate import zupt
from accelnav.estimate.kf import position_fix
from accelnav.hil_sim.sim.sensor import simulate
from accelnav.model.load import load_model


def assert_same(accel, clipped, model, params=None) -> int:
    """Record, window pass and candidates against the reference, bit for bit; returns the candidates' count."""
    p = zupt.resolved(model, params or zupt.ZuptParams())
    x, ok, R = zupt._prepared(accel, clipped, model)
    x0, ok0, R0 = ref._prepared(accel, clipped, model)
    assert np.array_equal(ok, ok0)
    assert np.array_equal(x.view(np.int64), x0.view(np.int64)), "x differs in some bit"
    assert np.array_equal(R, R0)
    w = zupt.window_samples(model, p)
    got = zupt._windows(x, ok.all(axis=1), R + p.tremor**2, w, p.var_k)
    want = ref.windows(x0, ok0, R0, w, p.tremor, p.var_k)
    for name, g, e in zip(("means", "wvar"), got[:2], want[:2], strict=True):
        bits, bits0 = g.view(np.int64), e.view(np.int64)
        assert np.array_equal(bits, bits0), f"{name} differs at {np.argwhere(bits != bits0)[:3]}"
    assert np.array_equal(got[2], want[2]), f"centres differ at {np.flatnonzero(got[2] != want[2])[:5]}"
    c, c0 = zupt.candidates(accel, clipped, model, p), ref.candidates(accel, clipped, model, p)
    assert np.array_equal(c, c0), f"candidate samples differ at {np.flatnonzero(c != c0)[:5]}"
    return len(zupt.intervals(c))


def test_bench_stop_and_go_and_its_decisions():
    """The bench's record (stop-and-go tiled), the candidates and the decision on them as with the reference's."""
    model = load_model(None)
    s = simulate(model, "stop_and_go", 200.0, seed=7)
    accel = np.resize(s.accel, (60_000, s.accel.shape[1]))
    clipped = np.zeros(accel.shape, dtype=bool)
    assert assert_same(accel, clipped, model) > 100
    p = zupt.resolved(model, zupt.ZuptParams())
    got = zupt.decide_rests(accel, clipped, None, model, p)
    want = zupt.decide_rests(accel, clipped, ref.candidates(accel, clipped, model, p), model, p)
    assert [(d.start, d.stop, d.reason, d.evidence) for d in got.decisions] == [
        (d.start, d.stop, d.reason, d.evidence) for d in want.decisions
    ]


@pytest.mark.parametrize(
    "scenario,model_name,seconds,seed",
    [("walking_drift", "default", 40.0, 1), ("jogging", "foot_imu", 20.0, 1), ("tilting_mount", "default", 300.0, 1)],
)
def test_simulated(scenario, model_name, seconds, seed):
    model = load_model(None if model_name == "default" else MODELS / f"{model_name}.toml")
    s = simulate(model, scenario, seconds, seed=seed)
    assert assert_same(s.accel, s.clipped, model) > 3


@pytest.mark.parametrize("seed", range(6))
def test_random_records_with_bad_samples(seed):
    """Quiet stretches between moves, with NaN, inf and clipped samples, gaps of unusable rows (at the ends too)."""
    rng = np.random.default_rng(seed)
    model = load_model(None)
    n = int(rng.integers(2_000, 12_000))
    n_axes = len(model.axes)
    level = np.repeat(rng.normal(0, 1.5, size=(n // 200 + 1, n_axes)), 200, axis=0)[:n]
    loud = np.repeat(rng.random(n // 150 + 1) < 0.4, 150)[:n, None]
    accel = level * loud + rng.normal(0, 0.02 + 2.0 * loud, size=(n, n_axes))
    clipped = rng.random((n, n_axes)) < 0.002
    accel[rng.random((n, n_axes)) < 0.002] = np.nan
    accel[rng.random((n, n_axes)) < 0.0005] = np.inf
    for _ in range(3):  # gaps: a run of unusable rows on one axis
        a = int(rng.integers(0, n - 50))
        clipped[a : a + int(rng.integers(1, 40)), int(rng.integers(0, n_axes))] = True
    accel[:3, 0] = np.nan  # the record's first and last windows hold bad samples
    clipped[-2:, -1] = True
    assert assert_same(accel, clipped, model) > 10
    assert assert_same(accel, clipped, model, zupt.ZuptParams(window_s=0.05, tremor=0.0, var_k=3.0)) > 10


@pytest.mark.parametrize("n", [0, 1, 5, 11, 12])
def test_records_about_one_window_long(n):
    model = load_model(None)  # a window of 11 samples at its rate
    assert zupt.window_samples(model, zupt.ZuptParams()) == 11
    accel = np.random.default_rng(n).normal(0, 0.01, size=(n, len(model.axes)))
    assert_same(accel, np.zeros(accel.shape, dtype=bool), model)


def test_a_window_on_the_bound_is_quiet():
    """var_k set to one window's own statistic: that centre passes (at most var_k), as the reference says."""
    model = load_model(None)
    accel = np.random.default_rng(9).normal(0, 0.05, size=(400, len(model.axes)))
    x, ok, R = ref._prepared(accel, np.zeros(accel.shape, dtype=bool), model)
    p = zupt.ZuptParams()
    w = zupt.window_samples(model, p)
    quiet = ref.windows(x, ok, R, w, p.tremor, p.var_k)[3]
    k = 200
    var_k = float(quiet[k] / x.shape[1])
    got = zupt._windows(x, ok.all(axis=1), R + p.tremor**2, w, var_k)[2]
    want = ref.windows(x, ok, R, w, p.tremor, var_k)[2]
    assert want[k] and np.array_equal(got, want)
    assert 0 < want.sum() < len(want) - w  # the bound splits the record: some windows above it, some on or below


@pytest.mark.parametrize("phi, c1, eps_mean", [(0.99, 0.08, 0.13), (0.999, -0.05, 0.07), (0.95, 3.0, 0.5),
                                               (0.99, 0.08, 0.0), (0.99, 0.0, 0.1), (1.0, 0.08, 0.1)])  # fmt: skip
def test_the_settled_bias_powers_change_no_bit(phi, c1, eps_mean):
    """The record's bias eps_mean - c1 phi^k with numpy's powers up to where the bias settled and zeros after
    (zupt._bias_powers) is numpy's whole-record one bit for bit; where it cannot settle (eps_mean 0, phi 1) every
    power is numpy's, and without c1 none is needed."""
    n = 40_000
    full = phi ** np.arange(n)
    settled = zupt._bias_settled(phi, c1, eps_mean, n)
    lean = zupt._bias_powers(phi, settled, n)
    want, got = eps_mean - c1 * full, eps_mean - c1 * lean
    assert np.array_equal(got.view(np.int64), want.view(np.int64))
    np.testing.assert_array_equal(lean[:settled], full[:settled])
    if c1 == 0.0:
        assert settled == 0
    elif eps_mean == 0.0 or phi == 1.0:
        assert settled == n
    else:
        assert 0 < settled < n  # it did settle: the zeros were tested
        # and a power short of it would have changed a bit: the bound is not loose by orders
        assert eps_mean - c1 * full[settled // 2] != eps_mean


@pytest.mark.parametrize("chunk", [1, 7, 1000, 10**6])
def test_the_decision_of_a_record_read_in_chunks_is_the_decision_of_it_whole(default_model, chunk):
    """zupt.decide_rests_read (a streamed run's decision, read a chunk at a time) against decide_rests on the record
    in memory: the same candidates, verdicts, figures and words, and the same gravity axes, whatever the chunks."""
    arrays = simulate(default_model, "stop_and_go", 60.0, 3).to_arrays()
    accel, clipped = arrays["accel"].copy(), arrays["clipped"].copy()
    clipped[500:520, 0] = True  # unusable samples across chunk edges
    accel[900, 1] = np.nan
    fixes = [[position_fix(3000, 1.0, 0.5)], []]

    def read(s, e):
        return arrays["t"][s:e], accel[s:e], clipped[s:e]

    n, n_axes = accel.shape
    for cands in (None, zupt.candidates(accel, clipped, default_model)):
        ref = zupt.decide_rests(accel, clipped, cands, default_model, fixes=fixes)
        got = zupt.decide_rests_read(read, n, n_axes, cands, default_model, fixes=fixes, chunk=chunk)
        np.testing.assert_array_equal(got.candidates, ref.candidates)
        np.testing.assert_array_equal(got.mask, ref.mask)
        assert len(ref.decisions) > 5 and any(d.accepted for d in ref.decisions)
        words = ("start", "stop", "accepted", "reason", "evidence")
        assert [[getattr(d, k) for k in words] for d in got.decisions] == [
            [getattr(d, k) for k in words] for d in ref.decisions
        ]
        figures = ("still", "level", "v_before", "sd_before", "v_after", "sd_after", "chi2")
        np.testing.assert_array_equal(*(np.array([[getattr(d, k) for k in figures] for d in dec.decisions])
                                        for dec in (got, ref)))  # fmt: skip
    x, ok, _ = zupt._prepared(accel, clipped, default_model)
    xr, okr, _ = zupt._prepared_read(read, n, n_axes, default_model, chunk)
    assert x.tobytes() == xr.tobytes() and ok.tobytes() == okr.tobytes()
    assert zupt.gravity_axes_read(read, n, n_axes, default_model, chunk=chunk) == zupt.gravity_axes(
        accel, clipped, default_model
    )


def test_runs_spans_are_the_whole_pass_figures():
    """The detector holds a run's window figures at a time (zupt._Spans, the sums carried from span to span):
    spans asked in order, with gaps, of one centre, and at the record's first and last window, are the whole pass'
    doubles bit for bit (the whole pass held to the numpy above); a span behind what was asked is refused."""
    model = load_model(None)
    s = simulate(model, "stop_and_go", 60.0, seed=3)
    x, ok, R = zupt._prepared(s.accel, np.zeros(s.accel.shape, dtype=bool), model)
    p = zupt.resolved(model, zupt.ZuptParams())
    w = zupt.window_samples(model, p)
    means, wvar, _ = zupt._windows(x, ok.all(axis=1), R + p.tremor**2, w, p.var_k)
    n, h = len(x), w // 2
    spans = zupt._Spans(x, w)
    for a, b in [(h, h + 1), (h + 5, h + 40), (h + 40, h + 41), (1000, 1999), (3000, n - h - 7), (n - h - 1, n - h)]:
        m, v = spans.of(a, b)
        assert np.array_equal(m.view(np.int64), means[a:b].view(np.int64)), f"means of {a}..{b}"
        assert np.array_equal(v.view(np.int64), wvar[a:b].view(np.int64)), f"wvar of {a}..{b}"
    with pytest.raises(ValueError, match="asked in order"):
        spans.of(1000, 1001)
    with pytest.raises(ValueError, match="inside the record"):
        zupt._Spans(x, w).of(h - 1, h + 3)
