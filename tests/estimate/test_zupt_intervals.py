"""Rests given as intervals (zupt.read_zupt_file): the binary-search reader equals row-by-row painting."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.errors import UserError
from accelnav.estimate import zupt

NAMES = ["x", "y"]


def painted(rows: list[tuple], t: np.ndarray, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The reader as it was: every interval compared with every sample, rows applied in order."""
    mask = np.zeros((len(t), len(names)), dtype=bool)
    sig = np.full((len(t), len(names)), np.nan)
    for a, b, ax, sd in rows:
        within = (t >= a) & (t <= b)
        for j in range(len(names)) if ax is None else [names.index(ax)]:
            mask[within, j] = True
            if sd is not None:
                sig[within, j] = sd
    return mask, sig


def write(path, rows: list[tuple], axis: bool, sigma: bool) -> None:
    head = ["start_s", "end_s"] + ["axis"] * axis + ["sigma"] * sigma
    lines = [",".join(head)]
    for a, b, ax, sd in rows:
        lines.append(",".join([repr(a), repr(b)] + [ax] * axis + [repr(sd)] * sigma))
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("axis", [False, True])
@pytest.mark.parametrize("sigma", [False, True])
@pytest.mark.parametrize("clock", ["sorted", "shuffled"])
def test_intervals_equal_row_by_row_painting(tmp_path, axis, sigma, clock):
    """Overlapping intervals (a later row's sigma wins), ends exactly on samples, points, intervals outside
    the run, on a sorted and a shuffled clock: the same mask and sigma, element for element."""
    rng = np.random.default_rng(5)
    t = np.arange(3000) / 100.0
    if clock == "shuffled":
        t = rng.permutation(t)
    rows = []
    for _ in range(200):
        a = float(rng.choice([rng.uniform(-2, 32), round(rng.uniform(0, 30), 2)]))  # some exactly on a sample
        b = a + float(rng.choice([0.0, 0.01, rng.uniform(0, 3)]))
        rows.append((a, b, str(rng.choice(NAMES)) if axis else None, float(rng.uniform(0.001, 0.1)) if sigma else None))
    path = tmp_path / "rests.csv"
    write(path, rows, axis, sigma)
    mask, sig = zupt.read_zupt_file(path, t, NAMES)
    want_mask, want_sig = painted([(float(repr(a)), float(repr(b)), x, s) for a, b, x, s in rows], t, NAMES)
    assert mask.any() and not mask.all()
    np.testing.assert_array_equal(mask, want_mask)
    np.testing.assert_array_equal(sig, want_sig)  # NaN where no interval (or no sigma column)


@pytest.mark.parametrize(
    ("row", "says"),
    [
        ("2.0,1.0,x,0.1", "row 3: end_s 1 is before start_s 2"),
        ("1.0,2.0,z,0.1", "row 3: axis 'z'; accepted: x, y"),
        ("1.0,2.0,y,0", "row 3: sigma is 0; accepted"),
        ("2.0,1.0,z,0", "row 3: end_s 1 is before"),  # the first fault of the first bad row
    ],
)
def test_bad_interval_rows_refused_at_their_row(tmp_path, row, says):
    path = tmp_path / "rests.csv"
    path.write_text(f"start_s,end_s,axis,sigma\n0.0,1.0,x,0.1\n{row}\n3.0,1.0,x,0.1\n")
    with pytest.raises(UserError, match=says):
        zupt.read_zupt_file(path, np.arange(500) / 100.0, NAMES)
