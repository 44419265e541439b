"""The one engine (accelnav.estimate.engine through accelnav.data.smoothing.smooth_file): every option taken
chunked at a small memory budget gives the one-chunk result, from every input format; what needs every sample
in memory is refused over the budget in one line before any work.

Chunked and one-chunk runs do the same operations in the same order; 1e-12 relative (to |value| + its sigma)
is the room the bounded tests leave for a compiler's contractions (tests/estimate/test_smooth_bounded.py).
"""

from __future__ import annotations

import gzip
from dataclasses import replace

import numpy as np
import pytest
from conftest import assert_rel_close

from accelnav.cli import main
from accelnav.data.runfile import load_run
from accelnav.data.smoothing import smooth_file
from accelnav.errors import UserError
from accelnav.estimate.engine import Job, Tune

RTOL = 1e-12
SMALL = 20_000  # bytes: a 3000-sample run in several chunks
LARGE = 1 << 34


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A simulated run file (truth, raw counts) and its recording as NPZ, CSV and gzip CSV, with fixes and rests."""
    folder = tmp_path_factory.mktemp("engine")
    sim = folder / "sim.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "30", "--seed", "4", "--out", str(sim)]) == 0
    arrays, _ = load_run(sim)
    t, accel = arrays["t"], arrays["accel"]
    np.savez(folder / "rec.npz", t=t, accel=accel, axis_names=arrays["axis_names"])
    text = "t_s,acc_x_m_s2,acc_y_m_s2\n" + "".join(
        f"{a:.17g},{b:.17g},{c:.17g}\n" for a, (b, c) in zip(t, accel, strict=True)
    )
    (folder / "rec.csv").write_text(text)
    (folder / "rec.csv.gz").write_bytes(gzip.compress(text.encode()))
    rows = ["time_s,axis,position_m,sigma_m"]
    for k in (1000, 1500, 2999):
        rows += [f"{t[k]:.4f},{ax},{arrays['r'][k, j]:.6f},0.05" for j, ax in enumerate("xy")]
    (folder / "fixes.csv").write_text("\n".join(rows) + "\n")
    (folder / "rests.csv").write_text("start_s,end_s\n2.0,4.0\n12.5,14.0\n")
    # a per-sample mask: two rests, the second of axis y alone
    rest = np.zeros((len(t), 2), dtype=bool)
    rest[(t >= 2.0) & (t <= 4.0)] = True
    rest[(t >= 12.5) & (t <= 14.0), 1] = True
    np.savez(folder / "mask.npz", rest=rest)
    return folder


def _pair(inputs, tmp_path, source, stages=("filt", "smooth"), covariances=False, **kw):
    """(chunked outcome, its file, one-chunk outcome, its file) of the same request."""
    job = Job(stages=stages, full=True, covariances=covariances)
    a = smooth_file(inputs / source, tmp_path / "a.npz", job=replace(job, budget=SMALL), **kw)
    b = smooth_file(inputs / source, tmp_path / "b.npz", job=replace(job, budget=LARGE), **kw)
    assert not a.plan.whole and a.plan.chunks > 3, a.plan
    assert b.plan.chunks == 1, b.plan
    return a, load_run(tmp_path / "a.npz")[0], b, load_run(tmp_path / "b.npz")[0]


def _same(got, ref, stages):
    for st in stages:
        sd = ref[f"{st}_sd"]
        assert_rel_close(got[f"{st}_x"], ref[f"{st}_x"], sd, RTOL, f"{st}_x")
        assert_rel_close(got[f"{st}_sd"], sd, 0.0, RTOL, f"{st}_sd")
    for key in ("t", "accel", "clipped", "zupt", "fixes", "zupt_candidates"):
        if key in got:  # the aids' keys: only where there are aids on the chunked path (the test says which)
            np.testing.assert_array_equal(got[key], ref[key], err_msg=key)


OPTIONS = {
    "plain": {},
    "fixes": {"fixes": "fixes.csv"},
    "rests given": {"zupt": "rests.csv"},
    "rests mask": {"zupt": "mask.npz"},
    "fixes and rests given": {"fixes": "fixes.csv", "zupt": "rests.csv"},
    "rests detected": {"zupt": "auto"},
    "fixes and detected rests": {"fixes": "fixes.csv", "zupt": "auto"},
}


@pytest.mark.parametrize("option", OPTIONS)
def test_each_option_chunked_equals_one_chunk(inputs, tmp_path, option):
    kw = {k: (v if v == "auto" else inputs / v) for k, v in OPTIONS[option].items()}
    a, got, b, ref = _pair(inputs, tmp_path, "sim.npz", **kw)
    _same(got, ref, ("filt", "smooth"))
    assert ("zupt" in got) == ("fixes" in got) == bool(kw)
    assert ("zupt_candidates" in got) == (kw.get("zupt") == "auto")
    if "zupt" in kw:
        assert got["zupt"].sum() > 100 and a.applied == b.applied
    if "fixes" in kw:
        assert len(got["fixes"]) == 6 and a.fixes == b.fixes == [3, 3]
    # the simulation's truth and raw counts are kept on both paths
    for key in ("r", "u", "a", "eps", "code"):
        if key in ref:
            np.testing.assert_array_equal(got[key], ref[key], err_msg=key)
    assert "r" in got


@pytest.mark.parametrize("option", ["fixes", "rests mask", "fixes and rests given", "rests detected"])
def test_aided_chunked_file_has_every_member_of_the_one_chunk_file(inputs, tmp_path, option):
    """Over the budget an aided run writes every member the one-chunk run does, the aids' NIS among them
    (fix_nis, zupt_nis: the consistency checks' evidence), the same numbers: the same operations in the same
    order, so the same doubles; 1e-12 relative is the compiler's room, as for the states."""
    kw = {k: (v if v == "auto" else inputs / v) for k, v in OPTIONS[option].items()}
    a, got, b, ref = _pair(inputs, tmp_path, "sim.npz", **kw)
    assert set(got) == set(ref)
    for key in ref:
        assert (got[key].shape, got[key].dtype) == (ref[key].shape, ref[key].dtype), key
    assert len(ref["fix_nis"]) == (6 if "fixes" in kw else 0)
    if "zupt" in kw:
        z = ref["zupt_nis"]
        assert len(z) > 100 and z[:, 3].sum() >= 2, "rests with their first updates"
        assert set(z[:, 1]) == {0.0, 1.0}
    np.testing.assert_allclose(got["fix_nis"], ref["fix_nis"], rtol=RTOL, atol=0)
    np.testing.assert_array_equal(got["zupt_nis"][:, [0, 1, 3]], ref["zupt_nis"][:, [0, 1, 3]])
    np.testing.assert_allclose(got["zupt_nis"][:, 2], ref["zupt_nis"][:, 2], rtol=RTOL, atol=0)
    _same(got, ref, ("filt", "smooth"))
    for key in set(ref) - {"fix_nis", "zupt_nis", "filt_x", "filt_sd", "smooth_x", "smooth_sd"}:
        np.testing.assert_array_equal(got[key], ref[key], err_msg=key)


@pytest.mark.parametrize("option", ["rests mask", "fixes and rests given", "rests detected"])
def test_default_file_keeps_each_rests_first_nis(inputs, tmp_path, option):
    """Without --full a run file keeps of ``zupt_nis`` each rest's first update's row (the NIS checks read no
    other), chunked as in one chunk: the same members, the full file's rows whose last column is 1, and the same
    NIS lines as the chunked full file."""
    kw = {k: (v if v == "auto" else inputs / v) for k, v in OPTIONS[option].items()}
    runs = {}
    for name, budget, full in (("a", SMALL, False), ("b", LARGE, False), ("f", SMALL, True)):
        job = Job(stages=("filt", "smooth"), budget=budget, full=full)
        runs[name] = smooth_file(inputs / "sim.npz", tmp_path / f"{name}.npz", job=job, **kw)
    assert not runs["a"].plan.whole and runs["b"].plan.whole and not runs["f"].plan.whole
    got, ref, every = (load_run(tmp_path / f"{name}.npz")[0] for name in "abf")
    assert set(got) == set(ref)
    for key in ref:
        assert (got[key].shape, got[key].dtype) == (ref[key].shape, ref[key].dtype), key
    z = every["zupt_nis"]
    first = z[z[:, 3] == 1]
    assert len(z) == every["zupt"].sum() and len(z) > 10 * len(first) and len(first) >= 2
    for rows in (got["zupt_nis"], ref["zupt_nis"]):
        np.testing.assert_array_equal(rows[:, [0, 1, 3]], first[:, [0, 1, 3]])
        np.testing.assert_allclose(rows[:, 2], first[:, 2], rtol=RTOL, atol=0)
    assert runs["a"].checks.nis == runs["f"].checks.nis and runs["a"].checks.nis


@pytest.mark.parametrize(
    "option, stages",
    [
        ("plain", ("smooth",)),
        ("fixes and rests given", ("smooth",)),
        ("rests detected", ("smooth",)),
        ("plain", ("filt",)),
    ],
)
def test_covariances_chunked_equal_the_one_chunk_file(inputs, tmp_path, option, stages):
    """--covariances over the budget: written chunk by chunk, the same members, shapes, dtypes and format as the
    one-chunk file, every number within 1e-9. Every axis takes the general path (no steady rows): its chunk
    boundaries fall where the covariances move fast (the first 50 samples: the (a, eps) block by 2e-4 to 1e-5 a
    sample) and where they move slowly (to the run's end)."""
    kw = {k: (v if v == "auto" else inputs / v) for k, v in OPTIONS[option].items()}
    a, got, b, ref = _pair(inputs, tmp_path, "rec.npz", stages, covariances=True, **kw)
    assert a.plan.chunk < 50 and a.plan.chunks > 100, a.plan
    assert set(got) == set(ref)
    assert str(got["format"]) == str(ref["format"]) == "accelnav-run/1"
    for key in got:
        assert (got[key].shape, got[key].dtype) == (ref[key].shape, ref[key].dtype), key
    st = ("filt", "smooth") if "smooth" in stages else stages
    _same(got, ref, st)
    for key in [f"{s}_P" for s in st] + ["filt_P_prior"]:
        d = np.sqrt(np.einsum("akii->aki", np.abs(ref[key])))
        assert_rel_close(got[key], ref[key], d[..., :, None] * d[..., None, :], 1e-9, key)
    sd = np.sqrt(np.einsum("akii->aki", ref["filt_P_prior"]))
    assert_rel_close(got["filt_x_prior"], ref["filt_x_prior"], sd, 1e-9, "filt_x_prior")
    for key in ("zupt", "fixes", "zupt_candidates"):
        if key in ref:
            np.testing.assert_array_equal(got[key], ref[key], err_msg=key)


def test_the_disk_check_counts_the_output_as_it_is_written(inputs, tmp_path):
    """chunked.disk_needed's output part is the file's per-sample bytes, compact, full or with covariances."""
    from accelnav.estimate.chunked import output_bytes

    n = 3000
    cases = [
        (Job(budget=SMALL), {}),
        (Job(budget=SMALL, full=True), {}),
        (Job(budget=SMALL), {"zupt": "rests.csv"}),
        (Job(budget=SMALL, covariances=True), {}),
        (Job(stages=("filt",), budget=SMALL, covariances=True), {}),
    ]
    for i, (job, kw) in enumerate(cases):
        out = tmp_path / f"{i}.npz"
        a = smooth_file(inputs / "rec.npz", out, job=job, **{k: inputs / v for k, v in kw.items()})
        assert not a.plan.whole
        with np.load(out) as f:
            big = sum(f[k].nbytes for k in f.files if n in f[k].shape[:2])
        stages = 2 if job.covariances and "smooth" in job.stages else len(job.stages)
        want = output_bytes(2, stages, full=job.full, covariances=job.covariances, marks=bool(kw) or job.covariances
                            and "smooth" in job.stages)  # fmt: skip
        assert big == n * want, (i, big, n * want)


@pytest.mark.parametrize("source", ["rec.npz", "rec.csv", "rec.csv.gz"])
@pytest.mark.parametrize("stages", [("smooth",), ("filt",), ("filt", "smooth")])
def test_every_input_format_streams_to_the_one_chunk_numbers(inputs, tmp_path, source, stages):
    a, got, b, ref = _pair(inputs, tmp_path, source, stages)
    assert a.streamed == ("NPZ" if source.endswith(".npz") else "CSV") and not b.streamed
    _same(got, ref, stages)
    assert {k for k in got if k.startswith(("filt_", "smooth_"))} == {
        f"{s}_{x}" for s in stages for x in "x sd".split()
    }


@pytest.mark.parametrize("option", ["plain", "fixes and rests given"])
def test_tune_chunked_equals_one_chunk(inputs, tmp_path, option):
    """--tune over the budget: its likelihood summed chunk by chunk, every evaluation reading the input again and
    making its aids per chunk; the same search as on one chunk in memory: the figures found, the likelihoods
    to 1e-9, and the run smoothed with them."""
    kw = {k: inputs / v for k, v in OPTIONS[option].items()}
    job = Job(stages=("filt", "smooth"), full=True, tune=Tune(max_evaluations=30, max_seconds=None))
    a = smooth_file(inputs / "rec.npz", tmp_path / "a.npz", job=replace(job, budget=SMALL), **kw)
    b = smooth_file(inputs / "rec.npz", tmp_path / "b.npz", job=replace(job, budget=LARGE), **kw)
    assert not a.plan.whole and a.plan.chunks > 3 and a.streamed == "NPZ", a.plan  # the input read in pieces
    assert b.plan.whole, b.plan
    (ra, _), (rb, _) = a.tune, b.tune
    assert ra.evaluations == rb.evaluations and ra.figures == rb.figures
    for f in ra.figures:
        assert ra.estimate[f] == pytest.approx(rb.estimate[f], rel=1e-9, abs=0), f
    for key in ("ll_start", "ll_estimate"):
        assert getattr(ra, key) == pytest.approx(getattr(rb, key), rel=1e-9, abs=0), key
    assert ra.ll_estimate > ra.ll_start  # the search moved: its path, not only its start, is compared
    assert a.model.noise == b.model.noise
    _same(load_run(tmp_path / "a.npz")[0], load_run(tmp_path / "b.npz")[0], ("filt", "smooth"))


# a library caller's own need (Job.in_memory: --plots and --tune stream now, no command sets it)
@pytest.mark.parametrize("flag, kw", [("my figure", {"job": Job(in_memory=("my figure",), budget=SMALL)})])
def test_what_needs_every_sample_in_memory_is_refused_over_the_budget(inputs, tmp_path, flag, kw):
    with pytest.raises(UserError) as exc:
        smooth_file(inputs / "rec.npz", tmp_path / "o.npz", **kw)
    assert "over the memory budget" in str(exc.value) and flag in str(exc.value) and "\n" not in str(exc.value)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("source", ["rec.npz", "sim.npz"])
@pytest.mark.parametrize("budget", [SMALL, LARGE])
def test_the_default_output_is_r_u_and_their_sds_at_float32_without_the_input(inputs, tmp_path, source, budget):
    """20 B per sample per axis at 2 axes (t's 8 B shared), the full file's r, u rounded to float32, no echo."""
    import zipfile

    from accelnav.data.runfile import csv_columns

    kw = {"zupt": "auto"} if source == "sim.npz" else {}
    smooth_file(inputs / source, tmp_path / "c.npz", job=Job(budget=budget), **kw)
    smooth_file(inputs / source, tmp_path / "f.npz", job=Job(budget=budget, full=True), **kw)
    c, _ = load_run(tmp_path / "c.npz")
    f, _ = load_run(tmp_path / "f.npz")
    assert str(c["format"]) == "accelnav-run/3" and str(f["format"]) == "accelnav-run/2"
    per_sample = {"t", "smooth_x", "smooth_sd"} | ({"zupt"} if kw else set())
    assert {k for k in c if np.ndim(c[k]) and len(c[k]) and k != "axis_names"} >= per_sample
    assert not {"accel", "clipped", "r", "u", "code", "filt_x"} & set(c)
    for key in ("smooth_x", "smooth_sd"):
        assert c[key].dtype == np.float32 and c[key].shape == (2, 3000, 2)
        np.testing.assert_array_equal(c[key], f[key][..., :2].astype(np.float32), err_msg=key)
    with zipfile.ZipFile(tmp_path / "c.npz") as z:
        data = sum(i.file_size for i in z.infolist() if i.filename.removesuffix(".npy") in per_sample)
    assert data / (3000 * 2) <= 24 - (0 if kw else 1)  # ~128 B of npy headers per member on top of 20 (21 with rests)
    names = [n for n, _ in csv_columns(c)]
    assert names == ["t_s", "x_smooth_r", "x_smooth_r_sd", "x_smooth_u", "x_smooth_u_sd"] + [
        "y_smooth_r", "y_smooth_r_sd", "y_smooth_u", "y_smooth_u_sd"]  # fmt: skip


def test_csv_and_compression_of_a_chunked_run_are_those_of_one_chunk(inputs, tmp_path, monkeypatch):
    """Written from the run file a piece at a time: the CSV's text and the deflated file's arrays are the one
    chunk's (every state, the truth columns too: --full --filter-states)."""
    import zipfile

    from accelnav.data import smoothing

    kw = {"zupt": "auto", "compress": True}
    job = Job(stages=("filt", "smooth"), full=True)
    old = smoothing.PIECE
    smoothing.PIECE = 700  # several pieces of the 3000 samples
    try:
        a = smooth_file(
            inputs / "sim.npz", tmp_path / "a.npz", job=replace(job, budget=SMALL), csv=tmp_path / "a.csv", **kw
        )
    finally:
        smoothing.PIECE = old
    b = smooth_file(
        inputs / "sim.npz", tmp_path / "b.npz", job=replace(job, budget=LARGE), csv=tmp_path / "b.csv", **kw
    )
    assert not a.plan.whole and b.plan.whole
    ta, tb = (tmp_path / "a.csv").read_text().splitlines(), (tmp_path / "b.csv").read_text().splitlines()
    assert ta[0] == tb[0] and "x_true_r" in ta[0] and "y_smooth_eps_sd" in ta[0] and len(ta) == len(tb) == 3001
    ra, rb = np.loadtxt(ta[1:], delimiter=","), np.loadtxt(tb[1:], delimiter=",")
    np.testing.assert_allclose(ra, rb, rtol=1e-9, atol=1e-300)  # %.10g text: the same digits but a last-bit tie
    with zipfile.ZipFile(tmp_path / "a.npz") as z:
        assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_DEFLATED}
    got, ref = load_run(tmp_path / "a.npz")[0], load_run(tmp_path / "b.npz")[0]
    _same(got, ref, ("filt", "smooth"))


@pytest.mark.parametrize("rests", ["intervals", "npz mask", "none"])
@pytest.mark.parametrize("every_s", [0.0, 0.03])
def test_given_aids_stream_chunk_by_chunk_across_chunk_boundaries(inputs, tmp_path, monkeypatch, rests, every_s):
    """Fixes and given rests on a streamed input: placed on its clock a piece at a time and made per chunk, never
    the input whole; a fix on a chunk's first sample and on its last, an interval straddling a boundary, two
    touching at one with two sigmas, a rest's every_s updates counted across it: the one-chunk numbers."""
    from accelnav.estimate import chunked, engine
    from accelnav.estimate.zupt import ZuptParams

    t = np.load(inputs / "rec.npz")["t"].tolist()
    c = chunked.chunk_samples(2, SMALL)
    b1, b2, b3 = 11 * c, 23 * c, 40 * c  # chunk boundaries
    fixes = [(b1, "x"), (b1 - 1, "y"), (b2, "y"), (b2 - 1, "x"), (b2, "x"), (2999, "x")]
    (tmp_path / "fixes.csv").write_text(
        "time_s,axis,position_m,sigma_m\n" + "".join(f"{t[k]!r},{ax},{0.01 * k},0.05\n" for k, ax in fixes)
    )
    spans = [(b1 - 7, b1 + 9, "x", 0.02), (b2 - 30, b2 - 1, "y", 0.03), (b2, b2 + 4, "y", 0.05), (b3 - 1, b3, "", 0.04)]
    kw = {"fixes": tmp_path / "fixes.csv"}
    if rests == "intervals":
        kw["zupt"] = tmp_path / "rests.csv"
        rows = [(t[a] - 0.003, t[b] + 0.003, x, sd) for a, b, ax, sd in spans for x in (ax or "xy")]
        kw["zupt"].write_text("start_s,end_s,axis,sigma\n" + "".join(f"{a!r},{b!r},{x},{sd}\n" for a, b, x, sd in rows))
    elif rests == "npz mask":
        mask = np.zeros((len(t), 2), dtype=np.uint8)
        for a, b, ax, _ in spans:
            mask[a : b + 1, [0, 1] if not ax else ["xy".index(ax)]] = 1
        kw["zupt"] = tmp_path / "rests.npz"
        np.savez(kw["zupt"], rest=mask)
    params = ZuptParams(every_s=every_s)
    whole = engine.Source.whole

    def not_whole(self):
        raise AssertionError("the chunked run read its input whole")

    monkeypatch.setattr(engine.Source, "whole", not_whole)
    a = smooth_file(inputs / "rec.npz", tmp_path / "a.npz", job=Job(stages=("filt", "smooth"), budget=SMALL, full=True),
                    zupt_params=params, **kw)  # fmt: skip
    monkeypatch.setattr(engine.Source, "whole", whole)
    b = smooth_file(inputs / "rec.npz", tmp_path / "b.npz", job=Job(stages=("filt", "smooth"), budget=LARGE, full=True),
                    zupt_params=params, **kw)  # fmt: skip
    assert a.streamed == "NPZ" and a.plan.chunks > 40 and a.plan.chunk == c and b.plan.whole
    got, ref = load_run(tmp_path / "a.npz")[0], load_run(tmp_path / "b.npz")[0]
    _same(got, ref, ("filt", "smooth"))
    assert a.fixes == b.fixes == [4, 2] and a.applied == b.applied
    assert len(got["fixes"]) == 6 and "zupt" in got
    # the aids' NIS: fixes on a chunk's first and last samples, a rest's first update told across a boundary and
    # across two touching spans (one rest): the one-chunk rows, the NIS itself to RTOL
    np.testing.assert_allclose(got["fix_nis"], ref["fix_nis"], rtol=RTOL, atol=0)
    assert got["zupt_nis"].shape == ref["zupt_nis"].shape
    np.testing.assert_array_equal(got["zupt_nis"][:, [0, 1, 3]], ref["zupt_nis"][:, [0, 1, 3]])
    np.testing.assert_allclose(got["zupt_nis"][:, 2], ref["zupt_nis"][:, 2], rtol=RTOL, atol=0)
    # without --full: each rest's first update's row, counted up front (touching spans one rest, every_s steps)
    monkeypatch.setattr(engine.Source, "whole", not_whole)
    smooth_file(inputs / "rec.npz", tmp_path / "c.npz", job=Job(budget=SMALL), zupt_params=params, **kw)
    kept, first = load_run(tmp_path / "c.npz")[0]["zupt_nis"], ref["zupt_nis"][ref["zupt_nis"][:, 3] == 1]
    np.testing.assert_array_equal(kept[:, [0, 1, 3]], first[:, [0, 1, 3]])
    np.testing.assert_allclose(kept[:, 2], first[:, 2], rtol=RTOL, atol=0)
    if rests != "none":
        # 2 rests an axis (y: two touching spans, one)
        assert len(got["zupt_nis"]) == got["zupt"].sum() and len(kept) == 4
        assert got["zupt"][b1 - 7 : b1 + 10, 0].sum() == (17 if not every_s else 6)
        assert got["zupt"][b2 - 30 : b2 + 5, 1].sum() == (35 if not every_s else 12)  # touching: one rest's steps
    else:
        assert not got["zupt"].any() and a.applied is None


@pytest.mark.parametrize("option", ["plain", "fixes and rests given"])
def test_plots_over_the_budget_draw_the_one_chunk_runs_envelope(inputs, tmp_path, option):
    """--plots over the budget: what the figures draw (each series' min and max per bin of samples, kept while the
    chunks are written) is the envelope of the one-chunk run's arrays: the input's double integration, the
    model's mean bias and the truth bit for bit, the states and their bands to 1e-9."""
    from accelnav.estimate.envelope import Envelope
    from accelnav.estimate.kf import bias_model
    from accelnav.estimate.pipeline import dead_reckoning
    from accelnav.model.design import axis_design

    kw = {k: inputs / v for k, v in OPTIONS[option].items()}
    job = Job(envelope=True)
    a = smooth_file(inputs / "sim.npz", tmp_path / "a.npz", job=replace(job, budget=SMALL), **kw)
    b = smooth_file(inputs / "sim.npz", tmp_path / "b.npz", job=replace(job, budget=LARGE), **kw)
    assert not a.plan.whole and a.plan.chunks > 3 and a.arrays is None, a.plan
    assert b.plan.whole and b.envelope is None, b.plan
    got, arrays, n = a.envelope, b.arrays, b.n
    assert got.bins == 1500 < n  # decimated: 3000 samples, 2 a bin
    want = Envelope(n)
    want.add("t", 0, arrays["t"])
    plain = dead_reckoning(arrays, b.model)
    for j in range(len(arrays["axis_names"])):
        want.add(f"dr/{j}", 0, plain[j])
        want.add(f"bias/{j}", 0, bias_model(axis_design(b.model, j), n))
        for key in ("r", "u", "a", "eps"):
            want.add(f"{key}/{j}", 0, arrays[key][:, j])
        for st in ("filt", "smooth"):
            x, sd = arrays[f"{st}_x"][j], arrays[f"{st}_sd"][j]
            want.add(f"{st}_x/{j}", 0, x)
            want.add(f"{st}_lo/{j}", 0, x - sd)
            want.add(f"{st}_hi/{j}", 0, x + sd)
    if kw:
        want.add("zupt", 0, arrays["zupt"])
        np.testing.assert_array_equal(got.extra["fixes"], arrays["fixes"])
    assert set(got.lo) == set(want.lo)
    for key in want.lo:
        for side in ("lo", "hi"):
            g, w = getattr(got, side)[key], getattr(want, side)[key]
            if key.startswith(("t", "dr/", "bias/", "r/", "u/", "a/", "eps/", "zupt")):
                np.testing.assert_array_equal(g, w, err_msg=f"{key} {side}")
            else:
                np.testing.assert_allclose(g, w, rtol=1e-9, atol=1e-12, err_msg=f"{key} {side}")


def test_plots_over_the_budget_are_drawn_from_the_envelope(inputs, tmp_path):
    from accelnav.plots.run import plot_outcome

    a = smooth_file(inputs / "sim.npz", tmp_path / "a.npz", job=Job(envelope=True, budget=SMALL))
    paths = plot_outcome(a, tmp_path / "p")
    assert [p.name for p in paths] == ["smooth.png", "fig10_bias.png", "fig11_position_filter.png",
                                       "fig12_position_smoother.png"]  # fmt: skip
    assert all(p.stat().st_size > 10_000 for p in paths)


def test_a_chunked_run_without_its_envelope_is_not_drawn(inputs, tmp_path):
    from accelnav.plots.run import plot_outcome

    a = smooth_file(inputs / "sim.npz", tmp_path / "a.npz", job=Job(budget=SMALL))
    with pytest.raises(ValueError, match="envelope=True"):
        plot_outcome(a, tmp_path / "p")
    assert not (tmp_path / "p").exists()


def test_detected_rests_of_a_streamed_input_never_hold_it_whole(inputs, tmp_path, monkeypatch):
    """--zupt auto over the budget on a streamed NPZ: the decision reads the stream a chunk at a time, and so do the
    chunked passes after it (the run never held whole), and the run file and the rest report are those of the same
    input held in memory, number for number."""
    from accelnav.estimate import engine

    seen, read_whole = [], []
    real, whole = engine._chunked, engine.Source.whole

    def spied(model, source, *args, **kwargs):
        seen.append((source.streamed, source.arrays is None))
        return real(model, source, *args, **kwargs)

    def spied_whole(self):
        read_whole.append(self.arrays is None)
        return whole(self)

    monkeypatch.setattr(engine, "_chunked", spied)
    monkeypatch.setattr(engine.Source, "whole", spied_whole)
    from accelnav.data.inputs import read_input

    held, _ = read_input(inputs / "rec.npz", None)  # as the run was read before: whole
    job = Job(budget=SMALL)
    a = smooth_file(inputs / "rec.npz", tmp_path / "a.npz", job=job, zupt="auto", zupt_report=tmp_path / "a.csv")
    b = smooth_file(held, tmp_path / "b.npz", job=job, zupt="auto", zupt_report=tmp_path / "b.csv")
    assert seen == [("NPZ", True), ("", False)] and True not in read_whole
    assert a.plan.chunks > 3 and sum(d.accepted for d in a.rests.decisions) > 0 and a.applied == b.applied
    got, ref = load_run(tmp_path / "a.npz")[0], load_run(tmp_path / "b.npz")[0]
    assert sorted(got) == sorted(ref) and "zupt_candidates" in got
    for key in ref:
        np.testing.assert_array_equal(got[key], ref[key], err_msg=key)
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()
