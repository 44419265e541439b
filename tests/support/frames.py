"""Telemetry bytes cut into frames, and a frame's kind: what the link tests build their damaged streams from."""

from __future__ import annotations

from accelnav.link.codec import cobs_decode


def split_frames(data: bytes) -> list[bytes]:
    """The COBS frames of a stream, each with its closing zero byte."""
    return [p + b"\0" for p in data.split(b"\0")[:-1]]


def frame_kind(man, f: bytes) -> str:
    """The name of an upstream frame by its type byte (the first of the decoded payload)."""
    t = cobs_decode(f[:-1])[0]
    return next(n for n, fr in man.frames.items() if fr["type"] == t and fr["direction"] == "up")
