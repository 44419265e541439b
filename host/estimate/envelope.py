"""A run's series decimated while they stream: the min and max of each series per bin of samples.

A figure of a long run draws at most a few thousand pixel columns; what a column shows of a line is the range of
its samples there. :class:`Envelope` keeps that range, per bin of ``n // bins`` consecutive samples, for every
series fed to it a chunk at a time, so that its memory is the bins' whatever the run's length, and the figures
drawn from it show every excursion a whole-array figure would (a min or max is exact: no sample is skipped).
Fed the same values, any cut of the run into chunks gives the same envelope, bit for bit.
"""

from __future__ import annotations

import numpy as np

BINS = 1500  # bins of a figure's time axis: more than the pixel columns of a panel (6.5 in at 110 dpi: 715)


class Envelope:
    """Per bin of samples, the min (``lo``) and max (``hi``) of each series added with :meth:`add`.

    A series is a key and (m,) or (m, k) values for samples s..s+m-1; a run of ``n <= bins`` samples keeps one
    bin per sample (the series themselves). ``extra``: small whole arrays kept beside (fixes, candidate rests)."""

    def __init__(self, n: int, bins: int = BINS) -> None:
        self.n = int(n)
        self.bins = max(1, min(int(bins), self.n))
        self.edges = np.arange(self.bins + 1, dtype=np.int64) * self.n // self.bins  # bin b: samples edges[b]..
        self.lo: dict[str, np.ndarray] = {}
        self.hi: dict[str, np.ndarray] = {}
        self.extra: dict[str, np.ndarray] = {}

    def add(self, key: str, s: int, values: np.ndarray) -> None:
        """Samples s..s+m-1 of series ``key`` (bools are kept as 0 and 1: their max says "any")."""
        v = np.asarray(values)
        v = v.astype(np.float64) if v.dtype == bool else v
        m = len(v)
        if m == 0:
            return
        if s < 0 or s + m > self.n:
            raise ValueError(f"envelope: samples {s}..{s + m - 1} outside 0..{self.n - 1}")
        b0 = int(np.searchsorted(self.edges, s, side="right")) - 1
        b1 = int(np.searchsorted(self.edges, s + m - 1, side="right")) - 1
        cuts = np.concatenate(([0], self.edges[b0 + 1 : b1 + 1] - s))
        lo, hi = np.minimum.reduceat(v, cuts, axis=0), np.maximum.reduceat(v, cuts, axis=0)
        if key not in self.lo:
            shape = (self.bins, *v.shape[1:])
            self.lo[key] = np.full(shape, np.inf)
            self.hi[key] = np.full(shape, -np.inf)
        np.minimum(self.lo[key][b0 : b1 + 1], lo, out=self.lo[key][b0 : b1 + 1])
        np.maximum(self.hi[key][b0 : b1 + 1], hi, out=self.hi[key][b0 : b1 + 1])

    def __contains__(self, key: str) -> bool:
        return key in self.lo

    def lines(self, key: str) -> np.ndarray:
        """The series as a figure draws it: per bin its min then its max, (2 bins, ...); NaN where a bin saw
        nothing but NaN."""
        lo, hi = self.lo[key], self.hi[key]
        out = np.empty((2 * self.bins, *lo.shape[1:]))
        out[0::2], out[1::2] = lo, hi
        out[~np.isfinite(out)] = np.nan
        return out

    def times(self) -> np.ndarray:
        """The time of each point of :meth:`lines`: a bin's first sample's, then its last's (series "t")."""
        return self.lines("t")
