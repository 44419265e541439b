"""The plain path from a stored transient plus one steady row (fastsmooth.steady_gains) against the full
per-sample computation (plain_gains(..., steady=False)), and its disk cache.

A test design with a short bias time constant settles in about 1 200 samples (the shipped model needs
about 8e5), so runs shorter than the transient, around it and several times longer are cheap.
Stated tolerance: 1e-12 relative, sigma-scaled, for means, standard deviations and covariances.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_rel_close

from accelnav.estimate import fastsmooth as fs
from accelnav.model.design import axis_design
from accelnav.model.edit import with_axis_bias, with_noise

RTOL = 1e-12


@pytest.fixture(scope="module")
def fast_design(default_model):
    ax = default_model.axes[0]
    m = with_noise(with_axis_bias(default_model, ax.name, ax.c1, ax.c2, 0.5), sigma_eps=0.05)
    return axis_design(m, 0)


@pytest.fixture(autouse=True)
def own_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ACCELNAV_CACHE_DIR", str(tmp_path / "cache"))
    fs.clear_gain_cache()
    fs.clear_steady_cache()
    yield
    fs.clear_gain_cache()
    fs.clear_steady_cache()


def _z(d, n, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * d.Ts
    return np.sin(0.7 * t) + 0.05 * t + rng.normal(0.0, 0.02, n)


def _assert_same(g, ref, d, z, what):
    xf0, xs0 = fs.plain_data(d, z, None, ref)
    xf1, xs1 = fs.plain_data(d, z, None, g)
    for P, P0, name in (
        (g.P_prior, ref.P_prior, "prior"),
        (g.P_post, ref.P_post, "filter"),
        (g.Ps, ref.Ps, "smoother"),
    ):
        sd0 = fs.packed_sd(P0)
        scale = np.sqrt(fs.unpack(P0)[..., fs._ROWS, fs._ROWS] * fs.unpack(P0)[..., fs._COLS, fs._COLS])
        assert_rel_close(P, P0, scale, RTOL, f"{what} {name} P")
        assert_rel_close(fs.packed_sd(P), sd0, 0.0, RTOL, f"{what} {name} sd")
    assert_rel_close(xf1, xf0, fs.packed_sd(ref.P_post), RTOL, f"{what} filter x")
    assert_rel_close(xs1, xs0, fs.packed_sd(ref.Ps), RTOL, f"{what} smoother x")


def test_short_around_and_long_runs_equal_the_full_computation(fast_design):
    d = fast_design
    st = fs.steady_gains(d)
    assert st is not None
    nt = len(st.rows)
    assert 100 < nt < 5000  # a real transient, and the forced one is short
    for n in (1, 2, 300, nt - 1, nt, nt + 1, 3 * nt + 7):
        g = fs.plain_gains(d, n)
        ref = fs.plain_gains(d, n, steady=False)
        assert len(ref.K) == n
        assert len(g.K) == min(n, nt)  # the transient plus the steady row; a shorter run its own rows only
        _assert_same(g, ref, d, _z(d, n), f"N={n}")


def test_rows_do_not_depend_on_n(fast_design):
    st = fs.steady_gains(fast_design)
    nt = len(st.rows)
    longer = fs._plain_rows(fast_design, 4 * nt)
    # every row but the probe's last (whose C is 0: no sample after it) is the same at any length
    assert np.array_equal(st.rows, longer[:nt])
    assert fs.steady_len(longer) == nt


def test_cache_hit_gives_identical_numbers(fast_design, tmp_path):
    d = fast_design
    first = fs.steady_gains(d)
    files = list(fs.steady_cache_dir().glob("steady-*.bin"))
    assert len(files) == 1
    n = 2 * len(first.rows) + 5
    z = _z(d, n)
    g1 = fs.plain_gains(d, n)
    out1 = fs.plain_data(d, z, None, g1)
    fs.clear_steady_cache()
    fs.clear_gain_cache()
    again = fs.steady_gains(d)
    assert again is not first and np.array_equal(again.rows, first.rows)
    g2 = fs.plain_gains(d, n)
    out2 = fs.plain_data(d, z, None, g2)
    assert g2 is not g1
    for a, b in zip((*out1, g1.P_post, g1.Ps), (*out2, g2.P_post, g2.Ps), strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("damage", ["value", "truncate", "extend", "magic", "empty"])
def test_corrupt_cache_is_ignored_and_rebuilt(fast_design, damage):
    d = fast_design
    good = fs.steady_gains(d)
    path = next(fs.steady_cache_dir().glob("steady-*.bin"))
    blob = bytearray(path.read_bytes())
    if damage == "value":  # same size, one payload double replaced: only the hash can tell
        blob[-8:] = np.float64(1e300).tobytes()
    elif damage == "truncate":
        blob = blob[:-8]
    elif damage == "extend":
        blob += bytes(8 * fs.SROW)
    elif damage == "magic":
        blob[:8] = b"XXXXXXXX"
    else:
        blob = bytearray()
    path.write_bytes(bytes(blob))
    fs.clear_steady_cache()
    rebuilt = fs.steady_gains(d)
    assert np.array_equal(rebuilt.rows, good.rows)
    assert path.read_bytes() != bytes(blob)  # rewritten
    fs.clear_steady_cache()
    assert np.array_equal(fs._load_steady(path, good.key).rows, good.rows)


def test_a_file_of_another_design_is_not_taken(fast_design, default_model):
    st = fs.steady_gains(fast_design)
    path = next(fs.steady_cache_dir().glob("steady-*.bin"))
    assert fs._load_steady(path, fs.steady_key(axis_design(default_model, 0))) is None
    assert fs._load_steady(path, st.key) is not None


def test_not_steady_within_the_probe_falls_back_to_the_full_computation(fast_design, monkeypatch):
    monkeypatch.setattr(fs, "PROBE_MAX", 600)
    assert fs.steady_gains(fast_design) is None
    assert not list(fs.steady_cache_dir().glob("steady-*.bin"))
    n = 2000
    g = fs.plain_gains(fast_design, n)
    assert len(g.K) == n and g.rows is None
    _assert_same(g, fs.plain_gains(fast_design, n, steady=False), fast_design, _z(fast_design, n), "fallback")


def test_masked_runs_keep_per_sample_gains(fast_design):
    n = 3000
    mask = np.ones(n, dtype=bool)
    mask[[5, 1500, 2999]] = False
    g = fs.plain_gains(fast_design, n, mask)
    assert len(g.K) == n and g.rows is None and g.K[1500].tolist() == [0.0] * 4


@pytest.mark.parametrize("chunk", [97, 1000, 100_000])
def test_chunked_path_uses_the_steady_rows_and_equals_the_full_computation(default_model, tmp_path, chunk):
    """Axis 0 all valid (steady rows throughout); axis 1 loses a sample after the transient, from which
    chunk on the chunked path returns to the per-sample update."""
    from accelnav.estimate import chunked

    m = default_model
    for ax in m.axes:
        m = with_axis_bias(m, ax.name, ax.c1, ax.c2, 0.5)
    m = with_noise(m, sigma_eps=0.05)
    nt = len(fs.steady_gains(axis_design(m, 0)).rows)
    n = 3 * nt + 11
    rng = np.random.default_rng(5)
    t = np.arange(n) / m.rate_hz
    accel = np.cumsum(rng.normal(0, 0.05, (n, len(m.axes))), axis=0)
    clipped = np.zeros(accel.shape, dtype=bool)
    clipped[2 * nt + 3, 1] = True
    out = tmp_path / "o.npz"
    chunked.smooth_bounded(m, n, chunked.array_reader(t, accel, clipped), out, chunk=chunk)
    f = np.load(out)
    for j in range(len(m.axes)):
        d = axis_design(m, j)
        ok = ~clipped[:, j]
        mask = None if ok.all() else ok
        ref = fs.plain_gains(d, n, mask, steady=False)
        xf, xs = fs.plain_data(d, np.where(ok, accel[:, j], 0.0), mask, ref)
        for key, x, P in (("filt", xf, ref.P_post), ("smooth", xs, ref.Ps)):
            sd = fs.packed_sd(P)
            assert_rel_close(f[f"{key}_x"][j], x, sd, RTOL, f"{key}_x axis {j}")
            assert_rel_close(f[f"{key}_sd"][j], sd, 0.0, RTOL, f"{key}_sd axis {j}")


def test_the_key_follows_what_the_rows_depend_on(fast_design):
    import dataclasses

    d = fast_design
    moved = dataclasses.replace(d, x0=np.asarray(d.x0) + 1.0, b=np.asarray(d.b) * 2.0)  # means only
    assert fs.steady_key(moved) == fs.steady_key(d)
    assert fs.steady_key(dataclasses.replace(d, R=d.R * 2.0)) != fs.steady_key(d)
    assert fs.steady_key(dataclasses.replace(d, P0=np.asarray(d.P0) * 2.0)) != fs.steady_key(d)
    n = 3 * len(fs.steady_gains(d).rows)
    g = fs.plain_gains(moved, n)
    ref = fs.plain_gains(moved, n, steady=False)
    _assert_same(g, ref, moved, _z(moved, n), "shifted x0, b")


def test_a_run_shorter_than_the_transient_computes_only_its_own_rows(fast_design, monkeypatch):
    """Fails on the unbounded probe: it computed 2^17 rows or more for any run, and kept them."""
    calls = []
    real = fs._plain_rows
    monkeypatch.setattr(fs, "_plain_rows", lambda d, n: calls.append(n) or real(d, n))
    n = 300
    g = fs.plain_gains(fast_design, n)
    assert calls == [n] and len(g.K) == n and g.rows is not None
    assert not list(fs.steady_cache_dir().glob("steady-*.bin"))  # unsettled rows are nobody's steady state
    _assert_same(g, fs.plain_gains(fast_design, n, steady=False), fast_design, _z(fast_design, n), "short")
    fs.clear_gain_cache()
    assert len(fs.plain_gains(fast_design, 5 * n).K) == 5 * n  # a longer run is not given the short one's rows


def test_a_run_longer_than_the_probe_is_steady_and_equals_the_full_computation(fast_design, monkeypatch):
    monkeypatch.setattr(fs, "_PROBE0", 1024)
    monkeypatch.setattr(fs, "PROBE_MAX", 4096)
    n = 3 * 4096 + 5
    g = fs.plain_gains(fast_design, n)
    assert g.rows is not None and len(g.K) < 4096 and fs.steady_gains(fast_design).settled
    assert len(list(fs.steady_cache_dir().glob("steady-*.bin"))) == 1
    _assert_same(g, fs.plain_gains(fast_design, n, steady=False), fast_design, _z(fast_design, n), "long")


def test_a_run_within_the_probe_settles_from_its_own_rows(fast_design, monkeypatch):
    monkeypatch.setattr(fs, "_PROBE0", 1024)
    calls = []
    real = fs._plain_rows
    monkeypatch.setattr(fs, "_plain_rows", lambda d, n: calls.append(n) or real(d, n))
    n = 5000
    g = fs.plain_gains(fast_design, n)
    assert calls == [n] and len(g.K) < n and fs.steady_gains(fast_design).settled
    _assert_same(g, fs.plain_gains(fast_design, n, steady=False), fast_design, _z(fast_design, n), "within")


def test_an_unsettled_run_keeps_its_rows_apart_for_runs_no_longer(fast_design, monkeypatch):
    """A run longer than _PROBE0 that ends inside the transient: its rows are kept as a prefix that a run of
    its length or less reads; never as steady rows, and a longer run computes its own."""
    monkeypatch.setattr(fs, "_PROBE0", 256)
    calls = []
    real = fs._plain_rows
    monkeypatch.setattr(fs, "_plain_rows", lambda d, n: calls.append(n) or real(d, n))
    n = 900  # inside the ~1 200-sample transient
    first = fs.steady_gains(fast_design, n)
    assert not first.settled and calls == [n]
    assert not list(fs.steady_cache_dir().glob("steady-*.bin")) and list(fs.steady_cache_dir().glob("prefix-*"))
    again = fs.steady_gains(fast_design, n - 100)  # from memory (the rows kept), the same first rows
    assert calls == [n] and np.array_equal(again.rows[: n - 100], first.rows[: n - 100]) and not again.settled
    fs.clear_steady_cache()
    from_file = fs.steady_gains(fast_design, n - 100)  # from the prefix file
    assert calls == [n] and np.array_equal(from_file.rows, first.rows[: n - 100]) and not from_file.settled
    fs.plain_gains(fast_design, n + 50)
    assert calls == [n, n + 50]
    m = n - 100
    g = fs.plain_gains(fast_design, m)
    _assert_same(g, fs.plain_gains(fast_design, m, steady=False), fast_design, _z(fast_design, m), "prefix")


def test_a_file_changed_after_it_was_read_is_checked_again(fast_design):
    """Every read verifies the seal: a file that passed once and is then edited in place is refused."""
    good = fs.steady_gains(fast_design)
    path = next(fs.steady_cache_dir().glob("steady-*.bin"))
    fs.clear_steady_cache()
    assert fs._load_steady(path, good.key) is not None
    blob = bytearray(path.read_bytes())
    blob[-8:] = np.float64(1e300).tobytes()  # same size, one value changed, in place
    path.write_bytes(bytes(blob))
    assert fs._load_steady(path, good.key) is None


def test_a_short_run_reads_the_files_first_rows_once(fast_design, monkeypatch):
    """Runs shorter than the transient take the first rows of the settled file: read and verified once per
    process (a fleet of short runs read them for every file), the same rows for each, a longer run reads."""
    monkeypatch.setattr(fs, "_BLOCK_ROWS", 256)  # the file read by blocks: a short run reads its first ones
    settled = fs.steady_gains(fast_design)
    fs.clear_steady_cache()
    reads = []
    real = fs._load_steady
    monkeypatch.setattr(fs, "_load_steady", lambda path, key, need=None: reads.append(need) or real(path, key, need))
    n = len(settled.rows) // 2
    first = fs.steady_gains(fast_design, n)
    again = fs.steady_gains(fast_design, n - 10)
    assert reads == [n] and again is first and not first.settled
    assert np.array_equal(first.rows[:n], settled.rows[:n])
    longer = fs.steady_gains(fast_design, len(first.rows) + 1)
    assert reads == [n, len(first.rows) + 1] and longer is not first


def test_a_fleet_of_runs_shorter_than_the_probe_computes_their_rows_once(fast_design, monkeypatch):
    """Runs shorter than _PROBE0 (a fleet's 1e5-row files) compute their rows once per process and take the
    kept rows after, with the outputs their own rows give to the bit; a longer run computes its own. Fails when
    each run computes its rows again (32 ms of a 1e5-row file's 80 ms of CPU, two axes)."""
    calls = []
    real = fs._plain_rows
    monkeypatch.setattr(fs, "_plain_rows", lambda d, n: calls.append(n) or real(d, n))
    n = 700  # inside the ~1 200-sample transient
    first = fs.steady_gains(fast_design, n)
    assert fs.steady_gains(fast_design, n - 50) is first and calls == [n] and not first.settled
    kept = fs.plain_gains(fast_design, n - 50)
    assert calls == [n]
    fs.clear_gain_cache()
    fs.clear_steady_cache()
    own = fs.plain_gains(fast_design, n - 50)
    assert calls == [n, n - 50]
    z = _z(fast_design, n - 50)
    for a, b in zip(fs.plain_data(fast_design, z, None, kept), fs.plain_data(fast_design, z, None, own), strict=True):
        assert np.array_equal(a, b)
    assert len(fs.steady_gains(fast_design, n + 50).rows) == n + 50 and calls == [n, n - 50, n + 50]
