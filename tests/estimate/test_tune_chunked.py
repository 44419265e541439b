"""The tuner's likelihood summed chunk by chunk (accelnav.estimate.tune.data_loglik): any cut of the run gives the
one-chunk figure, with aids on and across chunk edges and invalid samples; the time bound stops an evaluation
within a chunk, and a search its bound cuts short is said to be so before it starts.

The chunks carry the filter's prior between them and do the same steps, so only the order of the sums differs:
1e-12 relative."""

from __future__ import annotations

import logging
from types import SimpleNamespace

import numpy as np
import pytest
from support.tune_cases import TRUE, one_axis_model, process

from accelnav.estimate import tune as tune_mod
from accelnav.estimate.kf import zero_velocity
from accelnav.estimate.tune import RunData, data_loglik, loglik, search, with_figures


@pytest.fixture(scope="module")
def case():
    truth = one_axis_model(**TRUE)
    z, valid, extras = process(truth, 3000, 5)
    valid[1490:1530] = False  # a gap across the 1500-sample chunk edge
    z[700, 0] = np.nan
    # two aids at one sample, one at a chunk's first sample and one at its last: the replay's ranks at the edges
    fx = [*extras[0], zero_velocity(1000, 0.05), zero_velocity(1499, 0.05), zero_velocity(2999, 0.05)]
    return truth, z, valid, [fx]


@pytest.mark.parametrize("chunk", [2, 7, 100, 1000, 1500, 2999])
def test_the_likelihood_summed_chunk_by_chunk_is_the_one_chunk_figure(case, chunk):
    truth, z, valid, extras = case
    start = with_figures(truth, {"sigma_n": 3.0, "sigma_eps": 0.05, "R": 0.05})
    for m in (truth, start):
        whole = loglik(m, z, valid, extras)
        assert data_loglik(m, RunData.of(z, valid, extras)) == whole  # one chunk: the same sums
        got = data_loglik(m, RunData.of(z, valid, extras, chunk=chunk))
        assert got == pytest.approx(whole, rel=1e-12, abs=0)


def test_a_wrong_carry_between_chunks_would_show(case):
    """The test above can fail: the same run cut in two without the first half's prior is another figure."""
    truth, z, valid, extras = case
    whole = loglik(truth, z, valid, extras)
    fx = [m for m in extras[0] if m.k >= 1500]
    moved = [type(m)(m.k - 1500, m.h, m.z, m.R) for m in fx]
    halves = loglik(truth, z[:1500], valid[:1500], [[m for m in extras[0] if m.k < 1500]]) + loglik(
        truth, z[1500:], valid[1500:], [moved]
    )
    assert abs(halves - whole) > 1e-6 * abs(whole)


def test_the_time_bound_stops_an_evaluation_within_a_chunk_and_is_said_up_front(case, monkeypatch, caplog):
    """A clock that moves 1 s per chunk read: an evaluation takes 30 s, the bound is 5 s. The search stops within
    a chunk of the bound (not at the end of the evaluation it is in), and says before it starts how long an
    evaluation takes and how few fit."""
    truth, z, valid, extras = case
    clock = [0.0]
    reads = []
    data = RunData.of(z, valid, extras, chunk=100)
    inner = data.read

    def read(s, e):
        clock[0] += 1.0
        reads.append(s)
        return inner(s, e)

    monkeypatch.setattr(tune_mod, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    slow = RunData(data.n, data.n_axes, read, data.aids, data.chunk)
    with caplog.at_level(logging.INFO, logger="accelnav"):
        r = search(truth, slow, max_evaluations=300, max_seconds=5.0, intervals=False)
    # the evaluation the bound stopped is counted; none beyond the start finished, so the start is kept
    assert not r.converged and r.evaluations == 2 and r.ll_estimate == r.ll_start and not r.adopted
    assert len(reads) <= 30 + 6  # the start's 30 chunks, then the bound's 5 s and the chunk that passed it
    said = [rec.getMessage() for rec in caplog.records if "one likelihood evaluation" in rec.getMessage()]
    assert len(said) == 1 and "takes 30 s" in said[0] and "about 0 of the search's 300" in said[0], said


def test_a_callers_chunk_aids_of_the_wrong_shape_are_refused_before_the_likelihood_reads_them(case):
    """A RunData's aids may be a caller's own ChunkAids: its pieces are checked as the smoothing passes check them
    (chunked.checked_piece), so an h of 3 columns is refused in words, not read past its end by the kernel."""
    from accelnav.estimate import chunked
    from accelnav.estimate import fastsmooth as fs

    truth, z, valid, extras = case
    whole = fs.Extras.of(extras[0])

    class Aids:
        count = len(whole)

        def __init__(self, columns: int):
            self.columns = columns

        def between(self, s, e):
            a, b = np.searchsorted(whole.k, s), np.searchsorted(whole.k, e)
            h = np.ascontiguousarray(whole.h[a:b, : self.columns])
            ex = fs.Extras(whole.k[a:b], h, whole.z[a:b], whole.R[a:b], whole.order[a:b] - a)
            return chunked.Piece(ex, np.zeros(b - a), np.ones(b - a, dtype=bool))

    data = RunData.of(z, valid, extras, chunk=500)
    good = RunData(data.n, data.n_axes, data.read, [Aids(4)], data.chunk)
    assert data_loglik(truth, good) == pytest.approx(data_loglik(truth, data), rel=1e-12)  # the same aids: accepted
    bad = RunData(data.n, data.n_axes, data.read, [Aids(3)], data.chunk)
    with pytest.raises(ValueError, match=r"shapes .*\(\d+, 3\).*accepted: \(\d+, 4\)"):
        data_loglik(truth, bad)
