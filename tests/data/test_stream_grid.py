"""The streamed input's time and grid passes in C (accelnav.data.csvnum.time_block, grid_block) find what
their numpy twins (accelnav.data.stream._steps_numpy, _grid_numpy: the passes as they were) find, and a
streamed NPZ is refused with the very line either way: a NaN or an infinity, a stamp off the grid, data in
another unit, time not finite or going back. (Two stamps in one period
and a missing sample are told by the C and the twin alike, first test; a streamed input never gets that
far with them: its clock is irregular, and the time pass sends it to the whole reader.)

Blocks of 7 rows put block boundaries everywhere (a bad row first or last in its block)."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.data import csvnum
from accelnav.data import recording as rc
from accelnav.data.stream import NotStreamed, _grid_numpy, _steps_numpy, open_stream
from accelnav.errors import UserError

N = 700


@pytest.fixture(scope="module")
def mod():
    m = csvnum.csv_lib()
    if m is None:
        pytest.skip("no C compiler here: the grid pass takes its numpy twin")
    return m


def _block(rng, m, k):
    t = 5.0 + np.arange(m) * 0.01
    accel = rng.normal(0, rng.choice([1.0, 300.0, 3000.0]), (m, k))
    return t, accel


@pytest.mark.parametrize("seed", range(6))
def test_the_c_pass_finds_what_the_numpy_pass_finds(mod, seed):
    rng = np.random.default_rng(seed)
    kinds = {"nan": 0, "off": 0, "dup": 0, "gap": 0, "beyond": 0}
    for _ in range(300):
        m, k = int(rng.integers(1, 40)), int(rng.choice([1, 2, 3, 12]))  # 12 axes: more counts than C locals
        t, accel = _block(rng, m, k)
        if rng.random() < 0.3:
            accel[rng.integers(m), rng.integers(k)] = rng.choice([np.nan, np.inf, -np.inf])
        if rng.random() < 0.4:
            t[rng.integers(m)] += rng.choice([0.0026, -0.0026, 0.0024, -0.0049, 0.01, -0.01, 0.02])
        first = bool(rng.random() < 0.5)
        k_prev = int(rng.integers(496, 501))
        units = list(rng.choice(["g", "mg", "m/s^2", "counts"], k))
        ratio, thr = rc.unit_ratios(units, float(rng.choice([50.0, 490.0])))
        got = csvnum.grid_block(mod, t, accel, 5.0, 0.01, k_prev, first, ratio, thr)
        want = _grid_numpy(t, accel, 5.0, 0.01, k_prev, first, ratio, thr)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1]), (got, want)
        for name, hit in zip(("nan", "off", "dup"), got[0][:3], strict=True):
            kinds[name] += hit >= 0
        kinds["gap"] += got[0][3] == 1
        kinds["beyond"] += got[1].sum() > 0
    assert min(kinds.values()) >= 5, kinds  # every kind of finding was met, not only clean blocks


def _sorted_steps(steps):
    if steps is None:
        return None
    lo, hi, u, c = steps
    order = np.argsort(u, kind="stable")
    return lo, hi, list(np.asarray(u)[order]), list(np.asarray(c)[order])


@pytest.mark.parametrize("seed", range(6))
def test_the_c_time_pass_finds_what_the_numpy_pass_finds(mod, seed):
    rng = np.random.default_rng(seed)
    kinds = {"nonfinite": 0, "back": 0, "counted": 0, "over cap": 0}
    for _ in range(300):
        m = int(rng.integers(1, 40))
        t = 2.0 + np.arange(m) * 0.01 + rng.choice([0.0, 1e-12, 1e-3]) * rng.normal(size=m)
        if rng.random() < 0.2:
            t[rng.integers(m)] = rng.choice([np.nan, np.inf, -np.inf])
        if rng.random() < 0.3:
            t[rng.integers(m)] -= rng.choice([0.01, 0.02, 1.0])
        if rng.random() < 0.1:
            t[:] = 2.0  # every step 0 (and -0.0 among them, from a stamp minus itself)
        prev = None if rng.random() < 0.5 else float(t[0] - rng.choice([0.01, 0.0, -0.01]))
        cap = int(rng.choice([3, 1 << 16]))
        got = csvnum.time_block(mod, t, prev, cap)
        with np.errstate(invalid="ignore"):  # inf - inf: numpy says so, the C does not
            want = _steps_numpy(t, prev)
        assert got[:3] == want[:3], (got, want)
        if got[3] is None and want[3] is not None:  # over the C's cap: the caller counts them by numpy
            assert len(want[3][2]) > cap
            kinds["over cap"] += 1
        else:
            assert _sorted_steps(got[3]) == _sorted_steps(want[3]), (got, want)
            kinds["counted"] += got[3] is not None
        kinds["nonfinite"] += got[0] >= 0
        kinds["back"] += got[1] >= 0
    assert min(kinds.values()) >= 5, kinds


def test_evidence_equals_unit_evidence():
    rng = np.random.default_rng(3)
    accel = rng.normal(0, 400.0, (1000, 3))
    units = ["g", "m/s^2", "counts"]
    ratio, thr = rc.unit_ratios(units, 490.0)
    _, beyond = _grid_numpy(np.arange(1000) * 0.01, accel, 0.0, 0.01, -1, True, ratio, thr)
    assert np.array_equal(rc.evidence_of(accel, beyond, ratio), rc.unit_evidence(accel, units, 490.0))


def _npz(path, t, accel):
    np.savez(path, t=t, accel=accel, axis_names=np.array(["x", "y"]))
    return path


def _clean():
    rng = np.random.default_rng(1)
    return np.arange(N) / 100.0, rng.normal(0, 0.3, (N, 2))


def _spoil(what: str, row: int):
    t, a = _clean()
    if what == "nan":
        a[row, 1] = np.nan
    elif what == "inf":
        a[row, 0] = -np.inf
    elif what == "off the grid":
        t[row] += 0.003  # beyond a quarter period, while the steps stay regular (0.007 and 0.013 s)
    elif what == "in mg, said m/s^2":
        a = a * 1e4  # about 3000 of mg-sized numbers read as m/s^2: far past the sensor's +-490
    elif what == "time not finite":
        t[row] = np.nan
    elif what == "time goes back":
        t[row] = t[row - 1] - 0.01
    return t, a


SPOILS = ["nan", "inf", "off the grid", "in mg, said m/s^2", "time not finite", "time goes back"]


@pytest.mark.parametrize("row", [7, 13, 14, 350, N - 2])  # not the last: it sets the rate
@pytest.mark.parametrize("what", SPOILS)
def test_a_streamed_npz_is_refused_with_the_same_line_by_either_pass(tmp_path, monkeypatch, what, row, mod):
    path = _npz(tmp_path / "rec.npz", *_spoil(what, row))
    with pytest.raises(UserError) as by_c:
        open_stream(path, block=7)
    monkeypatch.setattr(csvnum, "csv_lib", lambda: None)
    with pytest.raises(UserError) as by_numpy:
        open_stream(path, block=7)
    assert not isinstance(by_c.value, NotStreamed)
    assert str(by_c.value) == str(by_numpy.value)
    said = {"nan": "not a number", "inf": "not a number", "off the grid": "off the", "in mg, said m/s^2": "likely in",
            "time not finite": "not a finite", "time goes back": "does not increase"}  # fmt: skip
    assert said[what] in str(by_c.value)
    assert what == "in mg, said m/s^2" or f"sample {row} (line {row + 1})" in str(by_c.value)


def test_a_clean_npz_streams_alike_by_either_pass(tmp_path, monkeypatch, mod):
    path = _npz(tmp_path / "rec.npz", *_clean())
    with open_stream(path, block=7) as st:
        got = st(0, st.n)
        ts = (st.t0, st.Ts)
    monkeypatch.setattr(csvnum, "csv_lib", lambda: None)
    with open_stream(path, block=7) as st:
        want = st(0, st.n)
        assert (st.t0, st.Ts) == ts
    assert all(np.array_equal(g, w) for g, w in zip(got, want, strict=True))


@pytest.mark.parametrize("comment_at", [None, 3, 300, 690])
def test_lines_are_named_alike_with_or_without_a_comment_among_the_rows(tmp_path, comment_at):
    """The streamed CSV keeps no lines store while every line after the header is a row (row k is on line
    first + k); a comment among the rows makes it keep them from there: either way the refusal names the
    line the whole reader names."""
    from accelnav.data.inputs import read_input

    t, a = _clean()
    lines = ["t_s,acc_x_m_s2,acc_y_m_s2"] + [f"{x:.9g},{y:.9g},{z:.9g}" for x, y, z in zip(t, *a.T, strict=True)]
    lines[601] = f"{t[600]:.9g},nan,0.1"
    if comment_at is not None:
        lines.insert(comment_at, "# a note among the rows")
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(UserError) as whole:
        read_input(path)
    with pytest.raises(UserError) as streamed:
        open_stream(path, block=7, workdir=tmp_path)
    assert str(streamed.value) == str(whole.value)
    before = comment_at is not None and comment_at <= 601  # the comment before the bad row moves it a line on
    assert f"sample 600 (line {602 + before})" in str(streamed.value)
