"""The rest decision holds per candidate only what it reads (issue 32, its memory at 1e8 samples): the events of
each direction are arrays in the order the list of tuples had (rests._Events), and each verdict reads its fields
from the decision's shared rows (rests._Decided) with the values the verdicts held before."""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from support.rests_reference import reference_events

from accelnav.estimate import rests, zupt
from accelnav.estimate.kf import position_fix
from accelnav.estimate.rests import Candidate, RestDecision
from accelnav.hil_sim.sim.sensor import simulate


@pytest.mark.parametrize("reverse", [False, True])
def test_the_events_are_the_sorted_list_as_arrays(reverse):
    """Candidates whose ends share a sample and one that starts at another's end, fixes on two axes at one sample
    and at a candidate's first and last samples: every event in the list's order, with its payload."""
    n = 200
    spans = [(10, 30), (20, 30), (30, 31), (50, 120), (119, 150)]
    cands = [Candidate(a, b, np.zeros(2), 1.0) for a, b in spans]
    fixes = [[position_fix(k, 0.5 * k, 0.1 + k) for k in (0, 29, 50, 50, 199)],
             [position_fix(k, -0.25 * k, 0.2 + k) for k in (50, 30, 10)]]  # fmt: skip
    ev = rests._Events(rests._Cands.of(cands, 2), fixes, n, reverse)
    want = reference_events(SimpleNamespace(n=n, cands=cands, fixes=fixes), reverse)
    kinds = {"test": 0, "fix": 1, "end": 2}
    assert len(ev) == len(want)
    assert ev.k.tolist() == [e[0] for e in want]
    assert ev.kind.tolist() == [kinds[e[2]] for e in want]
    assert ev.i.tolist() == [e[3][0] if e[2] == "fix" else e[3] for e in want]
    assert ev.z.tolist() == [e[3][1] if e[2] == "fix" else 0.0 for e in want]
    assert ev.var.tolist() == [e[3][2] if e[2] == "fix" else 0.0 for e in want]
    assert [ev.at(j) for j, e in enumerate(want) if e[2] == "fix"] == [e[3][3] for e in want if e[2] == "fix"]


def _eager(d) -> RestDecision:
    """The verdict as the eager construction made it: each field from the verdict's forward side and its side after."""
    r, i = d._rows, d._i
    f, c = r.found[i], r.cands[i]
    after = None if r.after is None else r.after[i]
    cb, vb, sb = r.before[i].tolist()
    ca, va, sa = [math.nan] * 3 if r.behind is None else r.behind[i].tolist()
    chi2 = cb if r.behind is None else max(cb, ca)
    level = math.sqrt(c.level.dot(c.level))
    return RestDecision(c.start, c.stop, i in r.acc, f.reason, rests._evidence(f, after), c.still, level, vb, sb, va,
                        sa, chi2)  # fmt: skip


def test_a_verdict_reads_the_fields_it_held(default_model):
    """Every field of every verdict of a stop-and-go drive, read from the rows, equals the one the verdict held (the
    same doubles, Python's types); a verdict holds no field of its own, and is a dataclass as before: equal to its
    eager twin field by field, hashed alike, replaced and turned into a dict."""
    arrays = simulate(default_model, "stop_and_go", 120.0, 3).to_arrays()
    cand = zupt.candidates(arrays["accel"], arrays["clipped"], default_model)
    found = zupt.decide_rests(arrays["accel"], arrays["clipped"], cand, default_model).decisions
    assert len(found) > 10 and any(d.accepted for d in found) and not all(d.accepted for d in found)
    fields = [f.name for f in dataclasses.fields(RestDecision)]
    for d in found:
        assert isinstance(d, rests._Decided)
        assert not set(fields) & set(d.__dict__)  # nothing held per verdict but its index (the evidence when read)
        want = _eager(d)
        for name in fields:
            got, ref = getattr(d, name), getattr(want, name)
            assert type(got) is type(ref), name
            assert got == ref or (isinstance(ref, float) and math.isnan(ref) and math.isnan(got)), name
        if not any(isinstance(v, float) and math.isnan(v) for v in dataclasses.astuple(want)):
            assert dataclasses.astuple(d) == dataclasses.astuple(want) and hash(d) == hash(want)
    d = found[0]
    moved = dataclasses.replace(d, accepted=not d.accepted, evidence="given")
    assert moved.accepted is not d.accepted and moved.evidence == "given" and moved.start == d.start
    assert dataclasses.asdict(d) == {name: getattr(d, name) for name in fields}


def test_the_short_rests_before_stands_are_picked_from_the_rows_as_from_the_sides(default_model):
    """The stands found moving from a rest before them, and the short rests that made them move, read from the forward
    pass' rows (reason codes, aids, the aids' kinds; bisected at once) equal what the verdicts' sides say, each
    looked at (a plain list of the same verdicts takes that path); the town drive has such a short rest."""
    arrays = simulate(default_model, "town_drive", 400.0, 3).to_arrays()
    p = zupt.resolved(default_model, zupt.ZuptParams())
    x, ok, R = zupt._prepared(arrays["accel"], arrays["clipped"], default_model)
    cands = rests._candidates(x, ok, R, zupt.intervals(zupt._detect(x, ok, R, default_model, p)))
    fixes = [[] for _ in default_model.axes]
    dec = rests._Decider(x, R, default_model.Ts, cands, fixes, p, rests.Clock(len(x), default_model.Ts))
    found, acc = dec.forward()
    shorts = dec._short_before_stands(found, acc)
    assert shorts and shorts == dec._short_before_stands(list(found), acc)
    moving = dec._moving_after_rest(found)
    assert moving and moving == dec._moving_after_rest(list(found))


def test_verdicts_keep_their_fields_through_pickle_copies_and_a_later_decision(default_model):
    """A verdict reads its fields from its decision's rows: a pickled or copied verdict reads the same ones, and a
    second decision on another record (new rows, new candidates) leaves the first decision's verdicts as they were."""
    import copy
    import pickle

    def decided(scenario: str, seed: int):
        arrays = simulate(default_model, scenario, 90.0, seed).to_arrays()
        cand = zupt.candidates(arrays["accel"], arrays["clipped"], default_model)
        return zupt.decide_rests(arrays["accel"], arrays["clipped"], cand, default_model).decisions

    first = decided("stop_and_go", 3)
    assert len(first) > 5
    before = [repr(dataclasses.astuple(d)) for d in first]  # repr: NaN fields compare equal
    for again in (pickle.loads(pickle.dumps(first)), copy.copy(first), copy.deepcopy(first)):
        assert [repr(dataclasses.astuple(d)) for d in again] == before
    other = decided("stop_and_go", 11)
    assert [repr(dataclasses.astuple(d)) for d in other] != before  # another record, other verdicts
    assert [repr(dataclasses.astuple(d)) for d in first] == before
