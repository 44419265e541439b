"""The general path's lean store (issue 32): the bounded smoother keeps the filter's posterior means alone
(chunked.GLROW doubles per sample) and makes each chunk's covariances again for the backward pass
(acn_chunkg_cov). The covariances need no data, so they must be the very doubles the forward pass had."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from accelnav.estimate import chunked
from accelnav.estimate import fastsmooth as fs
from accelnav.estimate.kf import position_fix, zero_velocity
from accelnav.model.design import axis_design
from accelnav.model.load import load_model


def _chunk_inputs(n: int):
    rng = np.random.default_rng(11)
    z = np.cumsum(rng.normal(0, 0.05, n))
    ok = np.ones(n, dtype=np.uint8)
    ok[n // 3 : n // 3 + 5] = 0
    ek = np.r_[np.arange(n // 4, n // 4 + 30, 2), n // 2, n // 2].astype(np.int64)
    eh = np.tile([0.0, 1.0, 0.0, 0.0], (len(ek), 1))
    eh[-2:] = [1.0, 0.0, 0.0, 0.0]  # two fixes on one sample, the second an outlier its gate rejects
    ez = np.zeros(len(ek))
    ez[-1] = 1e4
    eR = np.full(len(ek), 0.01)
    eg = np.zeros(len(ek))
    eg[-1] = 9.0
    return z, ok, ek, eh, ez, eR, eg


@pytest.mark.parametrize("last", [0, 1])
def test_the_remade_covariances_are_the_forward_pass_own(last):
    """acn_chunkg_cov from the chunk's first prior, its valid samples and the aids applied gives acn_chunkg_fwd's
    stored covariances bit for bit (a gated aid the filter rejected is skipped), and the lean forward pass the same
    means and carry as the full one."""
    d = axis_design(load_model(), 0)
    mod = fs._lib()
    ffi, lib = mod.ffi, mod.lib

    def p(a, t="double *"):
        return fs._ptr(ffi, a, t)

    n = 400
    z, ok, ek, eh, ez, eR, eg = _chunk_inputs(n)
    ne = len(ek)
    ax = fs._axis_struct(ffi, d)
    carry0 = np.concatenate([np.asarray(d.x0, dtype=np.float64), fs.pack(np.asarray(d.P0, dtype=float))])
    outs = {}
    for name, width in (("full", chunked.GROW), ("lean", chunked.GLROW)):
        carry, store = carry0.copy(), np.empty((n, width))
        xf, sf, applied = np.empty((n, 4)), np.empty((n, 4)), np.zeros(ne, dtype=np.uint8)
        args = (ax, n, last, p(z), p(ok, "unsigned char *"), ne, ffi.from_buffer("long[]", ek), p(eh), p(ez), p(eR),
                p(eg), p(applied, "unsigned char *"), p(carry), p(store), p(xf), p(sf))  # fmt: skip
        if name == "full":
            lib.acn_chunkg_fwd(*args, ffi.NULL, ffi.NULL, ffi.NULL, ffi.NULL)
        else:
            lib.acn_chunkg_fwd_lean(*args, ffi.NULL, ffi.NULL)
        outs[name] = (carry, store, xf, sf, applied)
    (cf, full, xf, sf, applied), (cl, lean, xl, sl, applied_l) = outs["full"], outs["lean"]
    assert applied.sum() == ne - 1 and not applied[-1]  # the outlier was rejected
    np.testing.assert_array_equal(applied_l, applied)
    for a, b in ((cl, cf), (lean, full[:, :4]), (xl, xf), (sl, sf)):
        np.testing.assert_array_equal(a, b)
    pst = np.empty((n, 10))
    lib.acn_chunkg_cov(ax, n, last, p(ok, "unsigned char *"), ne, ffi.from_buffer("long[]", ek), p(eh), p(eR),
                       p(applied, "unsigned char *"), p(carry0[4:].copy()), p(pst))  # fmt: skip
    np.testing.assert_array_equal(pst, full[:, 4:])
    # an aid marked not applied is not applied: the remade covariances then differ (the test can tell)
    skipped = applied.copy()
    skipped[0] = 0
    lib.acn_chunkg_cov(ax, n, last, p(ok, "unsigned char *"), ne, ffi.from_buffer("long[]", ek), p(eh), p(eR),
                       p(skipped, "unsigned char *"), p(carry0[4:].copy()), p(pst))  # fmt: skip
    assert not np.array_equal(pst, full[:, 4:])


def test_the_lean_store_smooths_to_the_full_stores_numbers(tmp_path):
    """smooth_bounded without covariances (lean store, on disk and in memory) writes the same doubles as with them
    (the full store, the covariances kept), over chunks that cut rests and a clipped stretch."""
    model = load_model()
    n, n_axes = 900, len(model.axes)
    rng = np.random.default_rng(4)
    t = np.arange(n) / model.rate_hz
    accel = np.cumsum(rng.normal(0, 0.05, (n, n_axes)), axis=0)
    clipped = np.zeros((n, n_axes), dtype=bool)
    clipped[300:311, 0] = True
    extras = [[position_fix(450, 1.0, 2.0)] + [zero_velocity(k, 0.05) for k in range(100, 180)] for _ in model.axes]
    gates = [[0.0] + [9.0] * 80 for _ in model.axes]
    read = chunked.array_reader(t, accel, clipped)
    got = {}
    cases = (("full", dict(covariances=True)), ("disk", {}), ("memory", dict(store_memory=1 << 30)),
             ("smoother alone", dict(stages=("smooth",))))  # fmt: skip
    for name, kw in cases:
        out = tmp_path / f"{name}.npz"
        chunked.smooth_bounded(model, n, read, out, chunk=97, extras=extras, gates=gates, full=True, **kw)
        with np.load(out) as f:
            got[name] = {k: f[k] for k in ("filt_x", "filt_sd", "smooth_x", "smooth_sd") if k in f.files}
    assert set(got["smoother alone"]) == {"smooth_x", "smooth_sd"}
    for name in ("disk", "memory", "smoother alone"):
        for k, v in got[name].items():
            np.testing.assert_array_equal(v, got["full"][k], err_msg=f"{name}: {k}")
    # the lean store's disk need is the means' alone
    assert chunked.disk_needed(n, n_axes, n_axes, full=True) - chunked.disk_needed(n, n_axes, 0, full=True) == (
        8 * n * n_axes * (chunked.GLROW - chunked.ROW)
    )


class _Twice(chunked.ChunkAids):
    """Rests at samples 100..179 made per chunk; ``change`` alters the aids of one chunk when it is asked for the
    second time (the backward pass), keeping their count."""

    def __init__(self, change) -> None:
        self.change, self.asked = change, {}
        self.count = 80

    def between(self, s: int, e: int) -> chunked.Piece:
        k = np.arange(max(s, 100), min(e, 180), dtype=np.int64)
        h, R = np.tile([0.0, 1.0, 0.0, 0.0], (len(k), 1)), np.full(len(k), 0.05**2)
        self.asked[s] = self.asked.get(s, 0) + 1
        if self.asked[s] == 2 and len(k):
            self.change(k, h, R)
        ex = fs.Extras(k, h, np.zeros(len(k)), R, np.arange(len(k)))
        return chunked.Piece(ex, np.zeros(len(k)), np.zeros(len(k), dtype=bool))


@pytest.mark.parametrize(
    "change",
    [
        lambda k, h, R: R.__setitem__(-1, 0.06**2),
        lambda k, h, R: h.__setitem__((0, slice(None)), [1.0, 0.0, 0.0, 0.0]),
        lambda k, h, R: k.__setitem__(0, k[0] - 1),  # still sorted and within the chunk
    ],
    ids=["R", "h", "sample"],
)
def test_the_backward_pass_refuses_other_aids_than_the_forward_pass(tmp_path, change):
    """The lean store's covariances are made again from the aids asked for again: aids of the same count but
    another R, h or sample the second time are refused (acn_aids_digest), not smoothed with the wrong
    covariances; the same aids twice smooth (the check passes what it should)."""
    model = load_model()
    n = 400
    t = np.arange(n) / model.rate_hz
    accel = np.cumsum(np.random.default_rng(5).normal(0, 0.05, (n, len(model.axes))), axis=0)
    read = chunked.array_reader(t, accel, np.zeros(accel.shape, dtype=bool))
    same = [_Twice(lambda k, h, R: None) for _ in model.axes]
    chunked.smooth_bounded(model, n, read, tmp_path / "same.npz", chunk=97, extras=same, full=True)
    assert all(a.asked[97] == 2 for a in same)  # the chunk with the rests was asked for twice
    other = [_Twice(change) for _ in model.axes]
    with pytest.raises(ValueError, match="differ from the forward pass's"):
        chunked.smooth_bounded(model, n, read, tmp_path / "other.npz", chunk=97, extras=other, full=True)


def _mixed_aids(n: int):
    """Aids that enter and leave the chunk kernels' loop of samples with no extra or a lone zupt at every turn:
    runs of zupts (with invalid samples inside, across chunk edges, at the run's first and last sample), a second
    zupt or a fix on a zupt's sample, gated zupts (one rejected), zupts of another h (e_u scaled, -0.0 entries)
    and of varying R."""
    k = np.sort(np.r_[0, 1, 2, 50:150, 100, 120, 200:220, 230, 231, 250:350, n - 3 : n]).astype(np.int64)
    h = np.tile([0.0, 1.0, 0.0, 0.0], (len(k), 1))
    R = 0.01 * (1.0 + (np.arange(len(k)) % 7))
    z, gate = np.zeros(len(k)), np.zeros(len(k))
    fix = np.nonzero(k == 120)[0][1]
    h[fix], z[fix] = [1.0, 0.0, 0.0, 0.0], 0.5  # a fix beside the zupt at 120 (and two zupts at 100)
    gate[(k >= 200) & (k < 220)] = 9.0
    z[k == 210] = 1e3  # its gate rejects it
    h[k == 230] = [0.0, 2.0, 0.0, 0.0]
    h[k == 231] = [-0.0, 1.0, -0.0, 0.0]
    return fs.Extras(k, h, z, R, np.arange(len(k))), gate


@pytest.mark.parametrize("collinear", [False, True], ids=["default prior", "r, u collinear"])
@pytest.mark.parametrize("cuts", [(), (97, 300)], ids=["one chunk", "three chunks"])
def test_the_chunk_kernels_are_acn_general_bit_for_bit(cuts, collinear):
    """acn_chunkg_fwd (its priors too), acn_chunkg_fwd_lean, acn_chunkg_cov and acn_chunkg_bwd_lean over chunks give
    acn_general's filter, aid and smoother numbers bit for bit, whichever of their loops steps a sample; with r and u
    collinear to 1e-16 in the first prior and no aid for 50 samples, the smoother gain's guarded fallback decides
    some steps (test_general_structured), and the backward kernel's gains taken two at a time take it alike."""
    d = axis_design(load_model(), 0)
    if collinear:
        P0 = np.array(d.P0, dtype=float)
        P0[:2, :2] = 1e9 * np.array([[1.0, 1.0 - 1e-16], [1.0 - 1e-16, 1.0]])
        d = dataclasses.replace(d, P0=P0)
    mod = fs._lib()
    ffi, lib = mod.ffi, mod.lib

    def p(a, t="double *"):
        return fs._ptr(ffi, a, t)

    n = 600
    rng = np.random.default_rng(17)
    z = np.cumsum(rng.normal(0, 0.05, n))
    ok = np.ones(n, dtype=np.uint8)
    ok[[1, 60, 61, 62, 149, 300, n - 1]] = 0
    ex, gate = _mixed_aids(n)
    if collinear:
        keep = ex.k >= 50
        ex, gate = (
            fs.Extras(*(np.ascontiguousarray(v[keep]) for v in (ex.k, ex.h, ex.z, ex.R)), np.arange(keep.sum())),
            gate[keep],
        )
    ref = fs.smooth_general(d, z, valid=ok.astype(bool), extras=ex, gates=gate[np.argsort(ex.order)])
    assert 0 < ref.applied.sum() < len(ex)  # the gate rejected one
    pp = ref.P_prior[1:]  # the priors the smoother's gains solve with
    pivot_u = (pp[:, 4] - pp[:, 1] ** 2 / pp[:, 0]) / pp[:, 4]  # the LDL' pivot of u, relative to its diagonal
    assert (pivot_u < 1e-12).any() == collinear
    edges = [0, *cuts, n]
    carry0 = np.concatenate([np.asarray(d.x0, dtype=np.float64), fs.pack(np.asarray(d.P0, dtype=float))])
    got = {key: np.empty((n, w)) for key, w in (("xpr", 4), ("ppr", 10), ("full", chunked.GROW), ("lean", 4),
                                                 ("xf", 4), ("pst", 10), ("xs", 4), ("sds", 4))}  # fmt: skip
    applied, ey, eS = np.zeros(len(ex), dtype=np.uint8), np.zeros(len(ex)), np.zeros(len(ex))
    carry_full, carry_lean, starts = carry0.copy(), carry0.copy(), []
    for s, e in zip(edges[:-1], edges[1:], strict=True):
        a, b = np.searchsorted(ex.k, [s, e])
        ek = np.ascontiguousarray(ex.k[a:b] - s)
        args = [p(np.ascontiguousarray(v[a:b])) for v in (ex.h, ex.z, ex.R, gate)]
        head = (ax := fs._axis_struct(ffi, d), e - s, int(e == n), p(z[s:e]), p(ok[s:e], "unsigned char *"), b - a,
                ffi.from_buffer("long[]", ek), *args)  # fmt: skip
        lib.acn_chunkg_fwd(*head, p(applied[a:b], "unsigned char *"), p(carry_full), p(got["full"][s:e]),
                           p(got["xf"][s:e]), p(np.empty((e - s, 4))), p(got["xpr"][s:e]), p(got["ppr"][s:e]),
                           p(ey[a:b]), p(eS[a:b]))  # fmt: skip
        starts.append(carry_lean[4:].copy())
        lean_applied = np.zeros(b - a, dtype=np.uint8)
        lib.acn_chunkg_fwd_lean(*head, p(lean_applied, "unsigned char *"), p(carry_lean), p(got["lean"][s:e]),
                                ffi.NULL, ffi.NULL, ffi.NULL, ffi.NULL)  # fmt: skip
        np.testing.assert_array_equal(lean_applied, applied[a:b])
        lib.acn_chunkg_cov(ax, e - s, int(e == n), p(ok[s:e], "unsigned char *"), b - a,
                           ffi.from_buffer("long[]", ek), args[0], args[2], p(applied[a:b], "unsigned char *"),
                           p(starts[-1]), p(got["pst"][s:e]))  # fmt: skip
    np.testing.assert_array_equal(carry_lean, carry_full)
    carry_b = np.zeros(14)
    for s, e in reversed(list(zip(edges[:-1], edges[1:], strict=True))):
        rc = lib.acn_chunkg_bwd_lean(fs._axis_struct(ffi, d), s, e - s, int(e == n), p(got["lean"][s:e]),
                                     p(got["pst"][s:e]), p(carry_b), p(got["xs"][s:e]), p(got["sds"][s:e]))  # fmt: skip
        assert rc == 0
    np.testing.assert_array_equal(applied.astype(bool), ref.applied[ex.order])
    for mine, theirs in ((got["xpr"], ref.x_prior), (got["ppr"], ref.P_prior), (got["full"][:, :4], ref.x_post),
                         (got["full"][:, 4:], ref.P_post), (got["xf"], ref.x_post), (got["lean"], ref.x_post),
                         (got["pst"], ref.P_post), (got["xs"], ref.xs), (ey, ref.y[ex.order]),
                         (eS, ref.S[ex.order])):  # fmt: skip
        np.testing.assert_array_equal(mine, theirs)
    np.testing.assert_array_equal(got["sds"], np.sqrt(ref.Ps[:, [0, 4, 7, 9]]))
