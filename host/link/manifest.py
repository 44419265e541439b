"""The telemetry manifest: the frame layout the MCU was built with (the JSON of :mod:`accelnav.codegen.frames`).

A log carries its manifest, so :func:`check_manifest` treats it as untrusted input before any of it
reaches numpy or C. :func:`sample_columns` reads the fields of sample frames in SI units by it.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

PROTOCOL = 3  # the manifest's protocol_version this decoder reads (codegen.frames.PROTOCOL_VERSION)


class Manifest:
    """The frame layout the MCU was built with (the JSON from codegen.frames)."""

    def __init__(self, data: dict):
        if isinstance(data, dict) and data.get("protocol") == "accelnav-telemetry":
            if data.get("protocol_version") != PROTOCOL:
                raise ValueError(
                    f"telemetry protocol {data.get('protocol_version')!r}: this accelnav reads protocol {PROTOCOL} "
                    "only (regenerate the firmware and record again, or read it with the accelnav that recorded it)"
                )
        check_manifest(data)  # it may come from someone else's log: nothing unchecked reaches numpy or C
        self.data = data
        self.axes: list[str] = list(data["axes"])
        self.input: str = data["input"]
        self.rate_hz: float = float(data["sample_rate_hz"])
        self.layout_hash: int = int(data["layout_hash"])
        self.model_sha256: str = data["model_sha256"]
        self.frames: dict[str, dict] = data["frames"]
        self.flags: dict[str, int] = data["flags"]
        self.axis_flags: dict[str, int] = data["axis_flags"]
        self.dtypes: dict[str, np.dtype] = {}
        self.by_type: dict[int, str] = {}
        for name, fr in self.frames.items():
            names, formats, offsets = ["type"], ["u1"], [0]
            for f in fr["fields"]:
                names.append(f["name"])
                formats.append(f["dtype"])
                offsets.append(f["offset"])
            self.dtypes[name] = np.dtype(
                {"names": names, "formats": formats, "offsets": offsets, "itemsize": fr["size"]}
            )
            self.by_type[fr["type"]] = name

    @classmethod
    def load(cls, path: str | Path) -> Manifest:
        return cls(json.loads(Path(path).read_text()))

    @classmethod
    def for_model(cls, model, form: str | None = None) -> Manifest:
        """Generate the manifest of ``model`` (runs the filter generator: a few seconds)."""
        from accelnav.codegen.generated import generate

        return cls(json.loads(generate(model, form=form)["acnframe.json"]))

    def text(self) -> str:
        return json.dumps(self.data, sort_keys=True)

    def up(self) -> list[str]:
        return [n for n, f in self.frames.items() if f["direction"] == "up"]

    def field(self, frame: str, name: str) -> dict:
        for f in self.frames[frame]["fields"]:
            if f["name"] == name:
                return f
        raise KeyError(f"{frame}.{name}")

    def raw_fields(self) -> tuple[str, ...]:
        return ("t1", "t2") if self.input == "duty_cycle" else ("code",)

    def checkpoints_sane(self, axis: np.ndarray, state: np.ndarray) -> np.ndarray:
        """Per checkpoint (``axis`` numbers, ``state`` images as rows of bytes) whether a firmware could
        have sent it: the axis exists and, for a gain-schedule axis, the row index in its image
        (``checkpoint_rows``: offset and rows per axis) lies inside the schedule's table."""
        axis = np.asarray(axis, np.int64)
        ok = axis < len(self.axes)
        for j, r in enumerate(self.data.get("checkpoint_rows") or ()):
            if r is None:
                continue
            at = np.flatnonzero(axis == j)
            if len(at):
                o = int(r["offset"])
                row = np.ascontiguousarray(np.asarray(state, np.uint8)[at, o : o + 4]).view("<u4").ravel()
                ok[at] = row < int(r["rows"])
        return ok

    def code_flags(self) -> list[int]:
        """The axis flags of a sample row for each 2-bit code of a compact block frame (0 updated,
        1 input refused: a rail, 2 no capture: a timeout, 3 missed by the board)."""
        af = self.axis_flags
        rail = 0 if self.input == "duty_cycle" else 1 << af["rail"]
        skip = 1 << af["skipped"]
        return [0, skip | rail, skip | (1 << af["timeout"]), skip | (1 << af["missed"])]


_NAME = re.compile(r"[^\x00-\x1f\x7f]{1,32}\Z")  # an axis name: it reaches field names and messages
_MAX_PAYLOAD = 249  # payload + CRC under 254 bytes: COBS adds exactly one byte (the decoder relies on it)
_NEEDED = {  # frame -> fields the decoder, the compact stream and the replay read (axis fields added below)
    "sample": ("seq", "index", "flags"),
    "ack": ("command", "index"),
    "cmd_stop": (),
    "block": ("index", "flags", "n", "run", "aflags"),
    "checkpoint": ("index", "flags", "axis", "run", "paused_at", "seq", "state"),
}


def _int(v, lo: int, hi: int) -> bool:
    return type(v) is int and lo <= v <= hi


def _bad(what: str) -> ValueError:
    return ValueError(f"not a usable accelnav telemetry manifest: {what}")


def check_manifest(data) -> None:
    """Refuse, with a ValueError of one line, a manifest whose shape the decoder cannot trust.

    A log carries its manifest, so this is untrusted input: the types and ranges of every key the
    decoder, :mod:`accelnav.link.compact` and :mod:`accelnav.link.replay` read are checked here,
    axis names must be short printable names, field dtypes must be plain numbers inside their
    frame, and the frames those modules need must be there with the fields they read. What the
    generator writes always passes."""
    if not isinstance(data, dict) or data.get("protocol") != "accelnav-telemetry":
        raise ValueError("not an accelnav telemetry manifest (key 'protocol')")
    _check_header(data)
    frames = data.get("frames")
    if not isinstance(frames, dict):
        raise _bad("'frames' is not a table")
    types = set()
    for name, fr in frames.items():
        _check_frame(name, fr, types)
    compact = "block" in frames or "checkpoint" in frames
    _check_needed(data, frames, compact)
    if compact:
        _check_compact(data, frames)


def _check_header(data: dict) -> None:
    """The keys outside the frames: axes, input, rate, hashes, the flag bit tables."""
    axes = data.get("axes")
    if not isinstance(axes, list) or not 1 <= len(axes) <= 3:
        raise _bad("'axes' is not a list of 1 to 3 names")
    # names only: what reaches C is the model's, and the replay takes a manifest only when it is the
    # one the model generates (accelnav.link.replay)
    if not all(isinstance(a, str) and _NAME.match(a) for a in axes) or len(set(axes)) < len(axes):
        raise _bad(f"'axes' {str(axes)[:80]}: accepted: distinct names of 1 to 32 printable characters")
    if data.get("input") not in ("analog", "duty_cycle"):
        raise _bad("'input' is not 'analog' or 'duty_cycle'")
    rate = data.get("sample_rate_hz")
    if type(rate) not in (int, float) or not (math.isfinite(rate) and rate > 0):
        raise _bad("'sample_rate_hz' is not a positive number")
    if not _int(data.get("layout_hash"), 0, 2**32 - 1) or not isinstance(data.get("model_sha256"), str):
        raise _bad("'layout_hash' or 'model_sha256' has the wrong type")
    for key, names, hi in (
        ("flags", ("reset", "resume", "replayed", "mismatch"), 15),
        ("axis_flags", ("rail", "skipped", "timeout", "missed"), 7),
    ):
        table = data.get(key)
        if not isinstance(table, dict) or not all(_int(v, 0, hi) for v in table.values()):
            raise _bad(f"{key!r} is not a table of bit numbers 0..{hi}")
        if not all(k in table for k in names):
            raise _bad(f"{key!r} lacks one of {', '.join(names)}")


def _check_frame(name: str, fr, types: set) -> None:
    """One frame: a direction, a type byte no other frame has (added to ``types``), a size, and fields
    that are plain integers inside it."""
    if not isinstance(fr, dict) or fr.get("direction") not in ("up", "down"):
        raise _bad(f"frame {name!r} has no direction 'up' or 'down'")
    if not _int(fr.get("type"), 0, 255) or fr["type"] in types or not _int(fr.get("size"), 1, _MAX_PAYLOAD):
        raise _bad(f"frame {name!r}: 'type' (a distinct byte) or 'size' (1..{_MAX_PAYLOAD}) is wrong")
    types.add(fr["type"])
    fields = fr.get("fields")
    if not isinstance(fields, list):
        raise _bad(f"frame {name!r}: 'fields' is not a list")
    for f in fields:
        if not isinstance(f, dict):
            raise _bad(f"frame {name!r}: a field is not a table")
        try:
            dt = np.dtype(f["dtype"]) if isinstance(f.get("dtype"), str) else None
        except (TypeError, ValueError, SyntaxError):
            dt = None
        if (
            dt is None
            or (dt.base.kind not in "ui")
            or not isinstance(f.get("name"), str)
            or not _int(f.get("offset"), 1, fr["size"] - dt.itemsize)
        ):
            raise _bad(f"frame {name!r}: a field is not a plain integer inside the frame")


def _check_needed(data: dict, frames: dict, compact: bool) -> None:
    """The frames the decoder, the compact stream and the replay read, with the fields they read."""
    axes = data["axes"]
    for name, need in _NEEDED.items():
        if name in ("block", "checkpoint") and not compact:
            continue
        if name not in frames:
            raise _bad(f"no {name!r} frame")
        have = {f["name"] for f in frames[name]["fields"]}
        if name in ("sample", "block"):
            need = need + tuple(f"{ax}.{k}" for ax in axes for k in _raw_fields(data["input"]))
        if name == "sample":
            need = need + tuple(f"{ax}.{k}" for ax in axes for k in ("flags", "r", "u", "a", "e"))
        missing = [n for n in need if n not in have]
        if missing:
            raise _bad(f"frame {name!r} lacks {', '.join(missing)}")


def _check_compact(data: dict, frames: dict) -> None:
    """The compact mode's sizes: block slots, state bytes per axis, the checkpoint's row entries."""
    axes = data["axes"]
    sb = data.get("state_bytes")
    if not _int(data.get("block_samples"), 1, 255) or not _int(data.get("checkpoint_samples"), 1, 2**24):
        raise _bad("'block_samples' or 'checkpoint_samples' is out of range")
    if not isinstance(sb, list) or len(sb) != len(axes) or not all(_int(n, 1, 4096) for n in sb):
        raise _bad("'state_bytes' is not one size per axis")
    shapes = {f["name"]: np.dtype(f["dtype"]).shape for f in frames["block"]["fields"]}
    slots = [n for n in _block_slots(axes, data["input"]) if shapes[n] != (data["block_samples"],)]
    ck = {f["name"]: np.dtype(f["dtype"]) for f in frames["checkpoint"]["fields"]}["state"]
    if slots or ck.shape != (max(sb),) or ck.base.itemsize != 1:
        raise _bad("the block's slots or the checkpoint's state do not match 'block_samples' / 'state_bytes'")
    rows = data.get("checkpoint_rows")
    if rows is not None and (not isinstance(rows, list) or len(rows) != len(axes)):
        raise _bad("'checkpoint_rows' is not one entry per axis")
    for r in rows or ():
        if r is not None and not (
            isinstance(r, dict) and _int(r.get("offset"), 0, 4092) and _int(r.get("rows"), 0, 2**32)
        ):
            raise _bad("a 'checkpoint_rows' entry is not an offset and a row count")


def _block_slots(axes, kind: str) -> list[str]:
    """The block frame's per-slot arrays: the axis codes and each axis' raw inputs."""
    return ["aflags"] + [f"{ax}.{k}" for ax in axes for k in _raw_fields(kind)]


def _raw_fields(kind: str) -> tuple[str, ...]:
    return ("t1", "t2") if kind == "duty_cycle" else ("code",)


def sample_columns(man: Manifest, samples: np.ndarray) -> dict[str, np.ndarray]:
    """Per-sample columns of sample frames in SI units: t, index, seq, flags, and per axis
    (n, n_axes) arrays of the raw input, r, u, a, eps and the axis flags."""
    n = len(samples)
    cols: dict[str, np.ndarray] = {
        "index": samples["index"].astype(np.int64),
        "seq": samples["seq"].astype(np.int64),
        "flags": samples["flags"].astype(np.int64),
        "t": samples["index"].astype(np.float64) / man.rate_hz,
    }
    for key in (*man.raw_fields(), "axis_flags", "r", "u", "a", "eps"):
        cols[key] = np.empty((n, len(man.axes)), np.int64 if key in ("code", "t1", "t2", "axis_flags") else np.float64)
    for j, ax in enumerate(man.axes):
        for key in man.raw_fields():
            cols[key][:, j] = samples[f"{ax}.{key}"]
        cols["axis_flags"][:, j] = samples[f"{ax}.flags"]
        for s, key in (("r", "r"), ("u", "u"), ("a", "a"), ("e", "eps")):
            frac = man.field("sample", f"{ax}.{s}")["frac"]
            cols[key][:, j] = np.ldexp(samples[f"{ax}.{s}"].astype(np.float64), -frac)
    return cols
