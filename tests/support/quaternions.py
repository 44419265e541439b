"""Quaternions (w, x, y, z) for the level-frame tests: a turn about one axis, and the inverse of a unit one."""

from __future__ import annotations

import numpy as np


def about(axis: int, angle: np.ndarray) -> np.ndarray:
    """(N, 4) turns by ``angle`` (N,) rad about body axis ``axis`` (0 x, 1 y, 2 z)."""
    q = np.zeros((np.size(angle), 4))
    q[:, 0] = np.cos(angle / 2)
    q[:, 1 + axis] = np.sin(angle / 2)
    return q


def conj(q: np.ndarray) -> np.ndarray:
    """The conjugate, the inverse of a unit quaternion."""
    return q * np.array([1.0, -1.0, -1.0, -1.0])
