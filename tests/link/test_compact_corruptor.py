"""An independent corruptor for the compact telemetry, and the properties the decoder keeps under it.

The corruptor (tests/support/compact_corruptor.py) knows the wire format only from its definition and
uses none of the decoder's code. It damages the firmware's own telemetry of N samples (host board,
cffi) with one kind of fault or all together, and the decoder reads the result in pieces of random size.

The truth is the firmware's own state of every sample (the same inputs run in
the state mode). Under every fault:

1. every delivered row is the true row of its index: raw input, axis flags and
   the four states of each axis, bit for bit;
2. the delivered indices strictly increase (one run: no reset, no reboot);
3. delivered + lost == E - S, where S is the index of the first original block
   or checkpoint that reached the decoder intact and E the furthest index one
   of them says (a block's end, a checkpoint's index): E - S == N unless the
   fault destroyed the stream's first or last frames (truncation, a bit flip or
   a drop at either end). Duplicates never count as delivered or lost.

Run as a script, it prints the table of faults, frames tried and counts.
"""

from __future__ import annotations

import sys
import time
from functools import cache

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.compact_corruptor import FAULTS, check, corrupt, decode_in_pieces, plain_session, split

N = 3000


@cache
def _telemetry():
    from accelnav.link.decoder import replay_for
    from accelnav.model.load import load_model

    man, _, frames, truth = plain_session(N)
    return man, replay_for(man, load_model()), frames, truth


@pytest.fixture(scope="module")
def tele():
    return _telemetry()


@pytest.mark.parametrize("kind", FAULTS)
def test_the_decoder_keeps_its_properties_under_each_fault(tele, kind):
    man, replay, frames, truth = tele
    for trial in range(4):
        rng = np.random.default_rng([FAULTS.index(kind), trial])
        data = corrupt(kind, frames, rng, N)
        rows, stats = decode_in_pieces(man, replay, data, rng)
        assert not check(man, truth, frames, data, rows, stats), (kind, trial)
        if kind in ("bitflip", "drop", "reorder", "future"):  # the decoder saw real damage or loss
            assert stats.lost + stats.bad_frames + stats.duplicates > 0


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck))
@given(st.lists(st.sampled_from(FAULTS[:-1]), min_size=1, max_size=4), st.integers(0, 2**32 - 1))
def test_the_decoder_keeps_its_properties_under_faults_hypothesis_combines(kinds, seed):
    man, replay, frames, truth = _telemetry()
    rng = np.random.default_rng(seed)
    data = b"".join(frames)
    for kind in kinds:  # each fault on what the one before left (cut back into frames at the delimiters)
        data = corrupt(kind, split(data) or frames, rng, N)
    rows, stats = decode_in_pieces(man, replay, data, rng)
    assert not check(man, truth, frames, data, rows, stats)


def main() -> None:
    """The table: per fault, trials, frames tried, delivered / lost / damaged / duplicates, and whether every
    property held."""
    man, replay, frames, truth = _telemetry()
    trials = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    print(
        f"{'fault':10} {'trials':>6} {'frames':>7} {'delivered':>10} {'lost':>10} {'damaged':>8} {'dups':>7}  outcome"
    )
    t0 = time.perf_counter()
    for kind in FAULTS:
        tot = np.zeros(5, np.int64)
        broken = []
        for trial in range(trials):
            rng = np.random.default_rng([100 + FAULTS.index(kind), trial])
            data = corrupt(kind, frames, rng, N)
            rows, stats = decode_in_pieces(man, replay, data, rng)
            tot += [data.count(b"\0"), len(rows), stats.lost, stats.bad_frames, stats.duplicates]
            broken += check(man, truth, frames, data, rows, stats)
        outcome = "held" if not broken else f"BROKEN x{len(broken)}: {broken[0]}"
        print(f"{kind:10} {trials:6d} {tot[0]:7d} {tot[1]:10d} {tot[2]:10d} {tot[3]:8d} {tot[4]:7d}  {outcome}")
    print(f"({time.perf_counter() - t0:.1f} s; {N} samples per trial, {len(frames)} frames before damage)")


if __name__ == "__main__":
    main()
