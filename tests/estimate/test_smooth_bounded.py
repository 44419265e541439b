"""The bounded-memory smoother (accelnav.estimate.chunked) and the host tools freed from max_run_s (issue 24).

Chunked and whole-array smoothing run the same operations in the same order, so they agree to the last bit
on one machine; the tests allow 1e-12 relative (to |value| + its sigma), room for a compiler that contracts
the multiply-adds of the two kernels differently, and a million times tighter than the 1e-9 at which both
are checked against the float64 reference (tests/estimate/test_fastsmooth.py).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import assert_rel_close, edited_model
from support.cli import run_cli as _run

from accelnav.cli import main
from accelnav.data.runfile import load_run
from accelnav.estimate import chunked
from accelnav.estimate import fastsmooth as fs
from accelnav.model.design import axis_design
from accelnav.model.load import load_model

RTOL = 1e-12


def _data(model, n, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / model.rate_hz
    accel = np.cumsum(rng.normal(0, 0.05, (n, len(model.axes))), axis=0) + rng.normal(0, 0.02, (n, len(model.axes)))
    clipped = np.zeros(accel.shape, dtype=bool)
    clipped[n // 3 : n // 3 + 11, 0] = True  # a clipped stretch across chunk edges
    clipped[n // 2, -1] = True
    accel[(n - 1) // 2, 0] = np.nan  # a missing value is skipped as on the whole path
    return t, accel, clipped


def _check_against_whole(model, out, accel, clipped):
    f = np.load(out)
    for j in range(len(model.axes)):
        ref = fs.smooth_plain(axis_design(model, j), accel[:, j], valid=~clipped[:, j])
        for key, x, P in (("filt", ref.x_post, ref.P_post), ("smooth", ref.xs, ref.Ps)):
            sd = fs.packed_sd(P)
            assert_rel_close(f[f"{key}_x"][j], x, sd, RTOL, f"{key}_x axis {j}")
            assert_rel_close(f[f"{key}_sd"][j], sd, 0.0, RTOL, f"{key}_sd axis {j}")


@pytest.mark.parametrize("n, chunk", [(1000, 97), (1000, 2), (1000, 999), (1000, 5000), (1, 4), (2, 2)])
def test_chunked_smoothing_equals_the_whole_array_path(tmp_path, n, chunk):
    """Split into many chunks (97, 2), a last chunk of one sample (999), one chunk, and the shortest runs."""
    model = load_model()
    t, accel, clipped = _data(model, n)
    out = tmp_path / "o.npz"
    info = chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), out, chunk=chunk)
    assert info["chunks"] == -(-n // chunk)
    _check_against_whole(model, out, accel, clipped)
    f = np.load(out)
    np.testing.assert_array_equal(f["t"], t)
    np.testing.assert_array_equal(f["accel"], accel)
    assert [p.name for p in tmp_path.iterdir()] == ["o.npz"], "temporary files left behind"


def test_the_smoother_alone_jumps_the_steady_covariance_and_keeps_the_numbers(tmp_path):
    """Without the filter's states written, the forward pass takes no covariance step per steady sample but one
    jump per chunk (acn_chunk_fwd_steady, steady_jump). Every output but the last sample's is untouched by it:
    the same bits as the whole path. The last sample's sds carry the jump: within 1e-9 of the per-sample steps,
    which themselves drift (each steady step adds the same increment and rounds it the same way: 1.6e-12 here,
    3e-11 at 1.2e6 samples, where the jump agrees with the same steps taken in long double)."""
    # bias time constants of 3 s, not 300 s: the gains settle in 8e3 samples, not 8e5
    model = edited_model([("T = 300.0", "T = 3.0"), ("T = 240.0", "T = 2.4")])
    n = fs._PROBE0 + 20_000  # the shortest run whose steady state is looked for
    t, accel, _ = _data(model, n)
    clipped = np.zeros(accel.shape, dtype=bool)  # all valid: the steady rows hold to the end
    st = fs.steady_gains(axis_design(model, 0), n)
    assert st is not None and st.settled and len(st.rows) < n // 10, "test setup: most samples must be steady"
    ends = []
    for chunk in (40_001, n):
        out = tmp_path / f"o-{chunk}.npz"
        chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), out, chunk=chunk, stages=("smooth",))
        f = np.load(out)
        assert "filt_x" not in f
        for j in range(len(model.axes)):
            ref = fs.smooth_plain(axis_design(model, j), accel[:, j])
            sd = fs.packed_sd(ref.Ps)
            assert_rel_close(f["smooth_x"][j], ref.xs, sd, RTOL, f"smooth_x axis {j}")
            assert_rel_close(f["smooth_sd"][j, :-1], sd[:-1], 0.0, RTOL, f"smooth_sd axis {j}")
            assert_rel_close(f["smooth_sd"][j, -1], sd[-1], 0.0, 1e-9, f"smooth_sd axis {j}, last sample")
        ends.append(f["smooth_sd"][:, -1])
    # a jump per chunk or one over the run: the same map raised to powers that add up
    assert_rel_close(ends[0], ends[1], 0.0, RTOL, "last sample's sds, chunked against one chunk")


def test_the_chunk_size_comes_from_the_budget():
    for n_axes in (1, 2, 3):
        per = chunked.sample_bytes(n_axes)
        for budget in (1 << 20, 256 << 20):
            k = chunked.chunk_samples(n_axes, budget)
            assert k * per <= budget < (k + 1) * per
    assert chunked.chunk_samples(2, 10) == 2  # never below the two samples a chunk needs


def test_temporary_files_are_removed_on_error(tmp_path):
    model = load_model()
    t, accel, clipped = _data(model, 500)

    def failing(s, e):
        if s >= 200:
            raise OSError("input went away")
        return t[s:e], accel[s:e], clipped[s:e]

    with pytest.raises(OSError):
        chunked.smooth_bounded(model, 500, failing, tmp_path / "o.npz", chunk=100)
    assert list(tmp_path.iterdir()) == []


def test_too_little_disk_is_refused_in_one_line_before_work(tmp_path, monkeypatch):
    import shutil
    from collections import namedtuple

    model = load_model()
    t, accel, clipped = _data(model, 100)
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(10**6, 10**6 - 1000, 1000))
    called = []
    with pytest.raises(chunked.UserError, match=r"need .* GB of disk .* are free") as exc:
        chunked.smooth_bounded(model, 100, lambda s, e: called.append(s), tmp_path / "o.npz")
    assert "\n" not in str(exc.value) and not called
    assert list(tmp_path.iterdir()) == []


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    path = tmp_path_factory.mktemp("bounded") / "sim.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "30", "--seed", "4", "--out", str(path)]) == 0
    return path


def test_smooth_over_its_memory_budget_runs_the_bounded_path(sim, tmp_path, capsys):
    """A budget of 0.02 MB sends a 3000-sample run to the chunked path; it gives the whole path's numbers."""
    argv = ["smooth", sim, "--out", tmp_path / "b.npz", "--memory-budget", "0.02", "--filter-states", "--full"]
    status, out, err = _run(argv, capsys)
    assert status == 0, err
    assert "smoothed in bounded memory" in out and "chunks of" in out
    status, _, err = _run(["smooth", sim, "--out", tmp_path / "w.npz", "--full"], capsys)
    assert status == 0, err
    b, _ = load_run(tmp_path / "b.npz")
    w, _ = load_run(tmp_path / "w.npz")
    for key in ("filt", "smooth"):
        sd = w[f"{key}_sd"]  # the whole path writes the standard deviations by default, covariances on request
        assert_rel_close(b[f"{key}_x"], w[f"{key}_x"], sd, RTOL, f"{key}_x")
        assert_rel_close(b[f"{key}_sd"], sd, 0.0, RTOL, f"{key}_sd")


@pytest.mark.parametrize("flags", [["--tune", "--tune-evaluations", "10"], ["--plots", "PLOTS"]])
def test_tune_and_plots_over_the_budget_are_done_chunked(sim, tmp_path, capsys, flags):
    """Once refused over the budget (they needed every sample in memory): --tune's likelihood is now summed
    chunk by chunk, and --plots draws from the outputs' envelope kept while the chunks are written."""
    flags = [str(tmp_path / "p") if f == "PLOTS" else f for f in flags]
    status, out, err = _run(["smooth", sim, "--out", tmp_path / "x.npz", "--memory-budget", "0.02", *flags], capsys)
    assert status == 0, err
    assert "smoothed in bounded memory" in out and "chunks of" in out
    if "--tune" in flags:
        assert "tune: sigma_n" in out and "evaluations" in out
    else:
        for name in ("smooth.png", "fig10_bias.png", "fig11_position_filter.png", "fig12_position_smoother.png"):
            assert (tmp_path / "p" / name).stat().st_size > 10_000, name


def test_fixes_and_auto_zupt_over_the_budget_give_the_whole_paths_numbers(sim, tmp_path, capsys):
    arrays, _ = load_run(sim)
    t, r = arrays["t"], arrays["r"]
    rows = ["time_s,axis,position_m,sigma_m"]
    for k in (1000, 1500, 2999):
        rows += [f"{t[k]:.4f},x,{r[k, 0]:.6f},0.05", f"{t[k]:.4f},y,{r[k, 1]:.6f},0.05"]
    (tmp_path / "fixes.csv").write_text("\n".join(rows) + "\n")
    argv = ["smooth", sim, "--fixes", tmp_path / "fixes.csv", "--zupt", "auto", "--filter-states", "--full"]
    status, out, err = _run([*argv, "--out", tmp_path / "b.npz", "--memory-budget", "0.05"], capsys)
    assert status == 0, err
    assert "smoothed in bounded memory" in out and "position fixes per axis: 3, 3" in out
    status, whole, err = _run([*argv, "--out", tmp_path / "w.npz"], capsys)
    assert status == 0, err
    # the aids' NIS checks, from the members fix_nis and zupt_nis: the same lines over the budget
    nis = [line for line in whole.splitlines() if "mean NIS" in line]
    assert len(nis) == 2 and any("over 6 fixes" in line for line in nis), whole
    assert [line for line in out.splitlines() if "mean NIS" in line] == nis, out
    b, _ = load_run(tmp_path / "b.npz")
    w, _ = load_run(tmp_path / "w.npz")
    for key in ("fix_nis", "zupt_nis"):
        np.testing.assert_array_equal(b[key], w[key], err_msg=key)  # the same operations: the same doubles
    assert b["zupt"].sum() > 100
    np.testing.assert_array_equal(b["zupt"], w["zupt"])
    np.testing.assert_array_equal(b["fixes"], w["fixes"])
    for key in ("filt", "smooth"):
        sd = w[f"{key}_sd"]  # the whole path writes the standard deviations by default, covariances on request
        assert_rel_close(b[f"{key}_x"], w[f"{key}_x"], sd, RTOL, f"{key}_x")
        assert_rel_close(b[f"{key}_sd"], sd, 0.0, RTOL, f"{key}_sd")


def test_a_recording_longer_than_max_run_s_is_smoothed(tmp_path, capsys):
    """max_run_s is the fixed-point C's range proof; the float64 host tools do not stop at it (fails before)."""
    short = edited_model([("max_run_s = 3600.0", "max_run_s = 10.0")])
    (tmp_path / "short.toml").write_text(short.text)
    n = 3000  # 30 s at 100 Hz, three times max_run_s
    t, accel, _ = _data(short, n)
    accel[np.isnan(accel)] = 0.0
    np.savez(tmp_path / "rec.npz", t=t, accel=accel)
    for cmd in ("smooth", "filter"):
        argv = [cmd, tmp_path / "rec.npz", "--model", tmp_path / "short.toml", "--out", tmp_path / f"{cmd}.npz"]
        status, _, err = _run(argv, capsys)
        assert status == 0, err
        arrays, _ = load_run(tmp_path / f"{cmd}.npz")
        assert len(arrays["t"]) == n
    # and the bounded path too
    argv = ["smooth", tmp_path / "rec.npz", "--model", tmp_path / "short.toml", "--out", tmp_path / "b.npz"]
    status, out, err = _run([*argv, "--memory-budget", "0.05"], capsys)
    assert status == 0 and "bounded memory" in out, err


def test_an_npz_recording_is_read_chunk_by_chunk_from_the_file(tmp_path):
    model = load_model()
    t, accel, clipped = _data(model, 700)
    np.savez(tmp_path / "rec.npz", t=t, accel=accel.astype(np.float32), clipped=clipped)
    with chunked.NpzReader(tmp_path / "rec.npz") as read:
        assert (read.n, read.n_axes) == (700, 2)
        got = read(123, 456)
        chunked.smooth_bounded(model, read.n, read, tmp_path / "o.npz", chunk=64)
    np.testing.assert_array_equal(got[0], t[123:456])
    np.testing.assert_array_equal(got[1], accel[123:456].astype(np.float32))
    np.testing.assert_array_equal(got[2], clipped[123:456])
    _check_against_whole(model, tmp_path / "o.npz", accel.astype(np.float32).astype(np.float64), clipped)


def test_a_compressed_npz_is_refused_in_one_line(tmp_path):
    np.savez_compressed(tmp_path / "rec.npz", t=np.arange(10.0), accel=np.zeros((10, 2)))
    with pytest.raises(chunked.UserError, match="compressed") as exc:
        chunked.NpzReader(tmp_path / "rec.npz")
    assert "\n" not in str(exc.value)


def _aids(model, n, seed=5):
    """Per axis: position fixes, and zero-velocity updates (gated, some rejected) over rests across chunk edges."""
    from accelnav.estimate.kf import position_fix, zero_velocity

    rng = np.random.default_rng(seed)
    extras, gates = [], []
    for j in range(len(model.axes)):
        fixes = [position_fix(int(k), float(rng.normal(0, 5)), 2.0) for k in rng.choice(n, 6)]  # repeats too
        rest = [zero_velocity(k, 0.05) for k in range(n // 4, min(n, n // 4 + 40))]
        wild = position_fix(n // 2, 1e4, 1.0)  # an outlier its gate rejects
        extras.append(fixes + rest + [position_fix(n - 1, 1.0, 3.0), position_fix(0, 0.0, 1.0), wild])
        gates.append([0.0] * 6 + [9.0 if j == 0 else 0.0] * len(rest) + [0.0, 0.0, 9.0])
    if len(model.axes) > 1:
        extras[-1], gates[-1] = [], None  # one axis with none: the plain path beside the general one
    return extras, gates


@pytest.mark.parametrize("n, chunk", [(1000, 97), (1000, 2), (1000, 999), (3, 2)])
def test_chunked_general_path_equals_the_whole_array_path(tmp_path, n, chunk):
    """Fixes and zero-velocity updates (gated on axis 0) split across chunks: the same numbers as smooth_general."""
    model = load_model()
    t, accel, clipped = _data(model, n)
    extras, gates = _aids(model, n)
    out = tmp_path / "o.npz"
    read = chunked.array_reader(t, accel, clipped)
    info = chunked.smooth_bounded(model, n, read, out, chunk=chunk, extras=extras, gates=gates)
    f = np.load(out)
    for j in range(len(model.axes)):
        d = axis_design(model, j)
        if extras[j]:
            ref = fs.smooth_general(d, accel[:, j], valid=~clipped[:, j], extras=extras[j], gates=gates[j])
            np.testing.assert_array_equal(info["applied"][j], ref.applied)
            assert not ref.applied[-1]  # the outlier: a rejection is compared too
        else:
            ref = fs.smooth_plain(d, accel[:, j], valid=~clipped[:, j])
        for key, x, P in (("filt", ref.x_post, ref.P_post), ("smooth", ref.xs, ref.Ps)):
            sd = fs.packed_sd(P)
            assert_rel_close(f[f"{key}_x"][j], x, sd, RTOL, f"{key}_x axis {j}")
            assert_rel_close(f[f"{key}_sd"][j], sd, 0.0, RTOL, f"{key}_sd axis {j}")
    assert [p.name for p in tmp_path.iterdir()] == ["o.npz"]


@pytest.mark.parametrize("verbosity, drawn", [(2, True), (0, False)])
def test_each_pass_shows_its_progress_unless_quiet(tmp_path, monkeypatch, capsys, verbosity, drawn):
    """A run past PROGRESS_AFTER seconds (here 0) draws the forward, backward and r, u passes on stderr; -q none."""
    from accelnav import progress

    model = load_model()
    t, accel, clipped = _data(model, 1000)
    monkeypatch.setattr(chunked, "PROGRESS_AFTER", 0.0)
    monkeypatch.setattr(progress, "VERBOSITY", verbosity)
    chunked.smooth_bounded(model, 1000, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz", chunk=97)
    err = capsys.readouterr().err
    for label in ("forward", "backward", "r, u"):
        assert (f"{label} [" in err) == drawn, err
    assert ("100.0%" in err) == drawn


def test_covariances_over_the_budget_are_written_chunk_by_chunk(sim, tmp_path, capsys):
    """smooth --covariances at a budget of 0.02 MB: chunked, the one-chunk file's members and numbers (1e-9)."""
    argv = ["smooth", sim, "--covariances"]
    status, out, err = _run([*argv, "--out", tmp_path / "b.npz", "--memory-budget", "0.02"], capsys)
    assert status == 0, err
    assert "smoothed in bounded memory" in out and "chunks of" in out
    status, out, err = _run([*argv, "--out", tmp_path / "w.npz"], capsys)
    assert status == 0 and "bounded memory" not in out, err
    b, _ = load_run(tmp_path / "b.npz")
    w, _ = load_run(tmp_path / "w.npz")
    assert set(b) == set(w) and str(b["format"]) == str(w["format"])
    for key in ("filt_P", "smooth_P", "filt_P_prior"):
        d = np.sqrt(np.einsum("akii->aki", w[key]))
        assert_rel_close(b[key], w[key], d[..., :, None] * d[..., None, :], 1e-9, key)


def test_covariances_with_invalid_samples_equal_one_chunk(tmp_path):
    """Clipped samples across a chunk edge (200..210, edge at 205) and a missing one: the chunked covariances
    are the one-chunk ones (1e-9)."""
    from accelnav.estimate.engine import smooth_arrays

    model = load_model()
    n = 600
    t, accel, clipped = _data(model, n)
    names = np.array([a.name for a in model.axes])
    read = chunked.array_reader(t, accel, clipped)
    chunked.smooth_bounded(model, n, read, tmp_path / "o.npz", chunk=41, covariances=True, axis_names=names)
    ref = smooth_arrays({"t": t, "axis_names": names, "accel": accel, "clipped": clipped}, model)
    got = np.load(tmp_path / "o.npz")
    for key in ("filt_P", "smooth_P", "filt_P_prior"):
        d = np.sqrt(np.einsum("akii->aki", ref[key]))
        assert_rel_close(got[key], ref[key], d[..., :, None] * d[..., None, :], 1e-9, key)
    for key in ("filt_x", "smooth_x", "filt_x_prior"):
        sd = np.sqrt(np.einsum("akii->aki", ref[key.replace("_x", "_P")]))
        assert_rel_close(got[key], ref[key], sd, 1e-9, key)


@pytest.mark.parametrize("covariances", [False, True])
def test_the_disk_check_refuses_one_byte_short_and_runs_at_the_count(tmp_path, monkeypatch, covariances):
    """smooth_bounded's disk check is the store plus the output as laid out: one byte less is refused in one line
    before any file is made; exactly the count runs, its per-sample members the counted bytes."""
    from accelnav.errors import UserError

    model = load_model()
    n = 500
    t, accel, clipped = _data(model, n)
    need = chunked.disk_needed(n, 2, n_stages=2, full=True, covariances=covariances)
    kw = dict(chunk=64, covariances=covariances, workdir=tmp_path / "w")
    (tmp_path / "w").mkdir()
    monkeypatch.setattr(chunked, "free_bytes", lambda _: need - 1)
    with pytest.raises(UserError, match="need .* GB of disk") as exc:
        chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz", **kw)
    assert "\n" not in str(exc.value) and not (tmp_path / "o.npz").exists()
    monkeypatch.setattr(chunked, "free_bytes", lambda _: need)
    chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz", **kw)
    with np.load(tmp_path / "o.npz") as f:
        assert sum(f[k].nbytes for k in f.files if n in f[k].shape[:2]) == n * chunked.output_bytes(
            2, 2, full=True, covariances=covariances
        )


class _EverySeventh(chunked.ChunkAids):
    """A zero-velocity update at every 7th sample of an axis, its ``nis`` rows [t, k, y^2 / S, applied]."""

    def __init__(self, n: int) -> None:
        self.k = np.arange(0, n, 7)
        self.count = self.nis_rows = len(self.k)

    def extras(self, s: int, e: int) -> fs.Extras:
        k = self.k[(self.k >= s) & (self.k < e)]
        m = len(k)
        return fs.Extras(k, np.tile([0.0, 1.0, 0.0, 0.0], (m, 1)), np.zeros(m), np.full(m, 1e-4), np.arange(m))

    def between(self, s: int, e: int) -> chunked.Piece:
        ex = self.extras(s, e)
        return chunked.Piece(ex, np.zeros(len(ex)), np.ones(len(ex), dtype=bool))

    def innovations(self, piece, done, y, S, t, s):
        return np.column_stack((t[piece.ex.k - s], piece.ex.k, y * y / S, done))


class _ThreeColumns(_EverySeventh):
    """A caller's ChunkAids whose h has 3 columns: the kernels read 4 a row."""

    def between(self, s: int, e: int) -> chunked.Piece:
        ex = self.extras(s, e)
        ex = fs.Extras(ex.k, np.ascontiguousarray(ex.h[:, :3]), ex.z, ex.R, ex.order)
        return chunked.Piece(ex, np.zeros(len(ex)), np.ones(len(ex), dtype=bool))


def test_a_callers_chunk_aids_of_the_wrong_shape_are_refused_before_the_kernels(tmp_path):
    model = load_model()
    t, accel, clipped = _data(model, 200)
    with pytest.raises(ValueError, match=r"shapes .*\(\d+, 3\).*accepted: \(\d+, 4\)"):
        chunked.smooth_bounded(model, 200, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz",
                               extras=[_ThreeColumns(200)], chunk=64, workdir=tmp_path)  # fmt: skip
    assert not (tmp_path / "o.npz").exists()


@pytest.mark.parametrize("covariances", [False, True])
def test_the_aids_nis_rows_are_streamed_as_the_whole_path_sees_them(tmp_path, monkeypatch, covariances):
    """smooth_bounded's ``nis`` member: each chunk's rows from ChunkAids.innovations, the aids' y and S as the
    filter met them (the lean and the full general kernels), the whole path's to the last bit (the same operations);
    its bytes are in the disk check: one byte short is refused before any file is made."""
    from accelnav.errors import UserError

    model = load_model()
    n = 500
    t, accel, clipped = _data(model, n)
    aids = _EverySeventh(n)
    need = chunked.disk_needed(
        n, 2, 2 if covariances else 1, n_stages=2, full=True, covariances=covariances, nis_rows=aids.nis_rows
    )
    kw = dict(extras=[aids], chunk=64, covariances=covariances, nis="nis", workdir=tmp_path)
    monkeypatch.setattr(chunked, "free_bytes", lambda _: need - 1)
    with pytest.raises(UserError, match="need .* GB of disk"):
        chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz", **kw)
    assert not (tmp_path / "o.npz").exists()
    monkeypatch.setattr(chunked, "free_bytes", lambda _: need)
    chunked.smooth_bounded(model, n, chunked.array_reader(t, accel, clipped), tmp_path / "o.npz", **kw)
    ref = fs.smooth_general(axis_design(model, 0), accel[:, 0], valid=~clipped[:, 0], extras=aids.extras(0, n),
                            gates=np.zeros(aids.count))  # fmt: skip
    with np.load(tmp_path / "o.npz") as f:
        got = f["nis"]
    assert got.shape == (aids.count, 4) and np.all(got[:, 3] == 1)
    np.testing.assert_array_equal(got[:, 0], t[aids.k])
    np.testing.assert_array_equal(got[:, 1], aids.k)
    np.testing.assert_array_equal(got[:, 2], ref.y * ref.y / ref.S)
