"""Quaternions (w, x, y, z) for the level frame: products, rotations, and the gyroscope integrated exactly.

Shared by the rest detector (which asks whether gravity's direction in the body turns as the gyroscope
says) and the levelling (which integrates the gyroscope between rests)."""

from __future__ import annotations

import numpy as np


def rotate(quat: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate the rows of ``v`` (N, 3) by the unit quaternions ``quat`` (N, 4) (w, x, y, z)."""
    w = quat[:, :1]
    u = quat[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def rotvec_quat(phi: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions of the rotation vectors ``phi`` (N, 3)."""
    angle = np.linalg.norm(phi, axis=1, keepdims=True)
    half = 0.5 * angle
    s = np.divide(np.sin(half), angle, out=np.full_like(angle, 0.5), where=angle > 1e-12)
    return np.concatenate([np.cos(half), s * phi], axis=1)


def qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton products p q of (N, 4) or (1, 4) quaternions (w, x, y, z)."""
    return qmul4(p.T, q.T).T


def qmul4(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton products p q of quaternions stored as (4, N) or (4, 1) columns (w, x, y, z)."""
    w1, x1, y1, z1 = p
    w2, x2, y2, z2 = q
    out = np.empty(np.broadcast_shapes(p.shape, q.shape))
    out[0] = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
    out[1] = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
    out[2] = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
    out[3] = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
    return out


def integrate(t: np.ndarray, gyro: np.ndarray) -> np.ndarray:
    """(N, 4) the attitude (body -> the first sample's frame) from the body rates ``gyro`` (N, 3) rad/s,
    each sample's rotation over its step taken exactly as a rotation vector; the products by a parallel
    prefix scan (log2 N numpy passes) rather than a loop over samples."""
    dt = np.diff(t, prepend=t[0])
    q4 = np.ascontiguousarray(rotvec_quat(gyro * dt[:, None]).T)  # (4, N): rows contiguous
    d = 1
    while d < q4.shape[1]:  # q[i] <- q[0] q[1] ... q[i] (Hillis-Steele)
        q4[:, d:] = qmul4(q4[:, :-d], q4[:, d:])
        d *= 2
    return q4.T / np.linalg.norm(q4, axis=0)[:, None]
