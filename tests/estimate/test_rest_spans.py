"""Given rests as runs of samples (zupt.RestSpans): made for any range of samples, they are the updates
zupt.axis_aids makes for the whole run; read a piece at a time from an NPZ mask or placed from intervals on a
clock read in pieces, they are read_zupt_file's per-sample mask."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.errors import UserError
from accelnav.estimate import zupt
from accelnav.estimate.fixes import Clock, read_fixes

NAMES = ["x", "y"]


def _mask_and_sigma(rng, n: int):
    """Rests of every length (a sample, runs that touch with two sigmas, one at each end of the run)."""
    mask = rng.random((n, 2)) < 0.02
    for j in range(2):
        for a in rng.integers(0, n, 12):
            mask[a : a + int(rng.integers(1, 120)), j] = True
    mask[:7, 0] = mask[-5:, 1] = True
    sig = np.where(rng.random((n, 2)) < 0.5, np.nan, 0.05)
    sig = np.repeat(sig[::37], 37, axis=0)[:n]  # the sigma changes inside rests too: touching runs
    return mask, np.where(mask, sig, np.nan)


@pytest.mark.parametrize("every_s", [0.0, 0.03])
@pytest.mark.parametrize("with_sigma", [False, True])
def test_updates_made_chunk_by_chunk_are_the_whole_runs(default_model, every_s, with_sigma):
    rng = np.random.default_rng(3)
    n = 2000
    mask, sig = _mask_and_sigma(rng, n)
    sig = sig if with_sigma else None
    p = zupt.ZuptParams(every_s=every_s)
    spans = zupt.RestSpans.of_mask(mask, sig)
    cuts = np.unique(np.concatenate(([0, n], rng.integers(0, n, 40), [6, 7, 8, n - 5])))  # on a rest's ends too
    for j in range(2):
        want = zupt.axis_aids(mask[:, j], None if sig is None else sig[:, j], default_model, p)
        parts = [spans.updates(j, int(s), int(e), default_model, p) for s, e in zip(cuts[:-1], cuts[1:], strict=True)]
        ks = np.concatenate([k for k, _ in parts])
        sd = np.concatenate([np.broadcast_to(d, k.shape) for k, d in parts])  # one for all: a 0-d sd
        np.testing.assert_array_equal(ks, want.k)
        np.testing.assert_array_equal(sd**2, want.R)
        given = np.full(n, np.nan) if sig is None else sig[:, j]  # each sample's own sigma, else --zupt-sigma's
        np.testing.assert_array_equal(sd, np.where(np.isfinite(given[ks]), given[ks], p.sigma))
        for (_, d), s, e in zip(parts, cuts[:-1], cuts[1:], strict=True):  # no rest here gives its own: one for all
            assert np.ndim(d) == (0 if np.isnan(given[s:e][mask[s:e, j]]).all() else 1)
        assert spans.count(j, default_model, p) == len(want.k) > 50
        assert all(((k >= s) & (k < e)).all() for (k, _), s, e in zip(parts, cuts[:-1], cuts[1:], strict=True))
    got_mask, got_sig = spans.painted()
    np.testing.assert_array_equal(got_mask, mask)
    np.testing.assert_array_equal(got_sig, sig if sig is not None else np.full(mask.shape, np.nan))


@pytest.mark.parametrize("compressed", [False, True])
def test_an_npz_mask_read_a_piece_at_a_time_is_the_whole_mask(tmp_path, monkeypatch, compressed):
    rng = np.random.default_rng(8)
    n = 5000
    mask, _ = _mask_and_sigma(rng, n)
    path = tmp_path / "rest.npz"
    (np.savez_compressed if compressed else np.savez)(path, rest=mask.astype(np.uint8))
    want, _ = zupt.read_zupt_file(path, np.arange(n) / 100.0, NAMES)
    monkeypatch.setattr(zupt, "_PIECE", 333)  # pieces that cut rests
    spans = zupt.read_rest_spans(path, Clock.of(np.arange(n) / 100.0), NAMES)
    np.testing.assert_array_equal(spans.painted()[0], want)
    np.testing.assert_array_equal(want, mask)
    bad = mask.astype(np.uint8)
    bad[4001, 1] = 2
    np.savez(path, rest=bad)
    with pytest.raises(UserError, match=r"rest mask sample 4001: \[1, 2\]|rest mask sample 4001: \[0, 2\]"):
        zupt.read_rest_spans(path, Clock.of(np.arange(n) / 100.0), NAMES)
    np.savez(path, rest=mask[:-1])
    with pytest.raises(UserError, match="has 4999 samples; the run has 5000"):
        zupt.read_rest_spans(path, Clock.of(np.arange(n) / 100.0), NAMES)


def test_intervals_and_fixes_placed_on_a_clock_read_in_pieces(tmp_path):
    """Interval ends and fixes exactly on samples, between them, on a piece's first and last sample: the placing
    of the whole clock in memory."""
    n = 1000
    t = 3.0 + np.arange(n) * 0.01
    piece = 64
    on = sorted(float(v) for v in (t[piece - 1], t[piece], t[2 * piece] + 0.004, t[3 * piece] - 0.005, t[0] - 0.004,
                                    t[-1] + 0.004))  # fmt: skip
    spans = [(on[0], on[1]), (on[2], on[2]), (on[3], on[5]), (float(t[piece - 1]), float(t[piece]))]
    (tmp_path / "rests.csv").write_text(
        "start_s,end_s,axis,sigma\n"
        + "".join(f"{a!r},{b!r},{ax},{0.1 * (i + 1)}\n" for i, (a, b) in enumerate(spans) for ax in NAMES)  # fmt: skip
    )
    (tmp_path / "fixes.csv").write_text(
        "time_s,axis,position_m,sigma_m\n" + "".join(f"{v!r},{ax},1.0,2.0\n" for v in on for ax in NAMES)
    )
    pieces = Clock(n, lambda s, e: t[s:e], float(np.median(np.diff(t))), piece=piece)
    want, want_sig = zupt.read_zupt_file(tmp_path / "rests.csv", t, NAMES)
    got, got_sig = zupt.read_rest_spans(tmp_path / "rests.csv", pieces, NAMES).painted()
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(got_sig, want_sig)
    assert want.any() and (want_sig == 0.4).any() and (want_sig == 0.1).any()
    assert read_fixes(tmp_path / "fixes.csv", pieces, NAMES) == read_fixes(tmp_path / "fixes.csv", t, NAMES)
    back = t.copy()
    back[700] = back[699] - 0.001
    with pytest.raises(UserError, match="not increasing near sample 640"):
        read_fixes(tmp_path / "fixes.csv", Clock(n, lambda s, e: back[s:e], piece=piece), NAMES)
