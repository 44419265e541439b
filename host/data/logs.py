"""A recorder log, or the firmware's telemetry, as the arrays of a run file."""

from __future__ import annotations

import numpy as np

from accelnav.errors import UserError
from accelnav.model.design import input_conversion
from accelnav.model.load import Model


def _decoded(log, model_text: str):
    """The decoded log, refused in one line when it holds no sample frame (every command on it needs one)."""
    from accelnav.link.logfile import LogError
    from accelnav.link.recorder import decode_log

    try:
        d = decode_log(log, model_text)
    except LogError as exc:
        raise UserError(str(exc)) from None
    if not len(d.frames["sample"]):
        raise UserError(
            f"{log}: 0 sample frames in {d.chunks} chunks ({d.stats['bytes']} bytes): a silent device or a "
            "recording stopped at once; nothing to process"
        )
    return d


def log_run_arrays(log, d=None, model_text: str = "") -> tuple[dict[str, np.ndarray], object]:
    """A recorder log as the arrays of an accelnav run file (and its model); what ``log export`` writes."""
    from accelnav.data.runfile import FORMAT
    from accelnav.link.telemetry import sample_columns
    from accelnav.model.load import ModelError, loads_model

    if d is None:
        d = _decoded(log, model_text)
    cols = sample_columns(d.manifest, d.frames["sample"])
    names = d.manifest.axes
    raw = d.manifest.raw_fields()
    skipped = (cols["axis_flags"] & (1 << d.manifest.axis_flags["skipped"])) != 0
    text = d.meta.get("model_toml") or model_text
    if not text:
        raise UserError(f"{log}: the log carries no model text (recorded with --manifest); export to .csv instead")
    try:
        model = loads_model(text, source=f"{log}:model_toml")
    except ModelError as exc:
        raise UserError(str(exc)) from None
    accel = np.empty((len(cols["t"]), len(names)))
    for j in range(len(names)):
        conv = input_conversion(model, j)
        accel[:, j] = (
            conv.accel(cols["code"][:, j]) if "code" in cols else conv.accel(cols["t1"][:, j], cols["t2"][:, j])
        )
    arrays = {
        "format": np.array(FORMAT),
        "model_toml": np.array(text),
        "model_source": np.array(f"{log}:model_toml"),
        "t": cols["t"],
        "axis_names": np.array(names),
        "accel": accel,
        "clipped": skipped,
        **{r: cols[r].astype(np.int32) for r in raw},
        "fw_x": np.stack(
            [np.stack([cols[s][:, j] for s in ("r", "u", "a", "eps")], axis=1) for j in range(len(names))]
        ),
        "fw_index": cols["index"],
        "fw_seq": cols["seq"],
        "fw_flags": cols["flags"],
        "fw_axis_flags": cols["axis_flags"],
        "host_time_ns": d.host_t_ns,
    }
    return arrays, model


def decoded_run(fitted: Model, run, telemetry: bytes, man) -> dict[str, np.ndarray]:
    """Run-file arrays from the firmware's sample frames (raw input, skip flags) plus the simulated truth.

    ``man`` is the frame manifest of the firmware built from ``fitted`` (the caller builds it).
    """
    from accelnav.link.telemetry import decode_all, replay_for, sample_columns

    frames, stats = decode_all(man, telemetry, replay_for(man, fitted))  # compact frames: the firmware's C replayed
    cols = sample_columns(man, frames["sample"])
    if stats.lost or len(cols["t"]) != len(run.t):
        raise UserError(f"telemetry: {len(cols['t'])} sample frames for {len(run.t)} samples, {stats.lost} lost")
    raw = [cols[k] for k in man.raw_fields()]
    skipped = (cols["axis_flags"] >> man.data["axis_flags"]["skipped"]) & 1
    arrays = {
        "t": cols["t"],
        "axis_names": np.array(run.axis_names),
        "accel": np.column_stack(
            [input_conversion(fitted, j).accel(*(r[:, j] for r in raw)) for j in range(len(run.axis_names))]
        ),
        "clipped": skipped.astype(bool),
        "fw_x": np.stack(
            [np.column_stack([cols[k][:, j] for k in ("r", "u", "a", "eps")]) for j in range(raw[0].shape[1])]
        ),
    }
    for k, r in zip(man.raw_fields(), raw, strict=True):
        arrays[k] = r.astype(np.int32)
    for key in ("r", "u", "a", "eps"):
        arrays[key] = getattr(run, key)
    return arrays
