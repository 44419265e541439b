"""A recorder log, or the firmware's telemetry, as the arrays of a run file.

Both go through :func:`run_arrays`: the sample frames' columns, converted by the model as the firmware
converts them, with its skip flags as the clipped samples and its own states as ``fw_x``.
"""

from __future__ import annotations

from pathlib import Path

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
    if d.stats["unreplayed"] and not len(d.frames["sample"]) and (d.meta.get("model_toml") or model_text):
        # a model was there, but the replay could not be made of it (not the firmware's, a compiler or cache
        # failure): the reason, not a request for what was given
        why = d.warnings[-1] if d.warnings else "no replay"  # decode_log's warnings are the replay's
        raise UserError(
            f"{log}: its {d.stats['unreplayed']} samples came in compact frames and no replay of the model "
            f"could be made to turn them into rows: {why.removeprefix(f'{log}: ')}"
        )
    if d.stats["unreplayed"] and not len(d.frames["sample"]):  # compact frames, no model: samples but no rows
        raise UserError(
            f"{log}: its {d.stats['unreplayed']} samples came in compact frames, which only the model the "
            "firmware was built with turns into rows: give --model M.toml"
        )
    if not len(d.frames["sample"]):
        raise UserError(
            f"{log}: 0 sample frames in {d.chunks} chunks ({d.stats['bytes']} bytes): a silent device or a "
            "recording stopped at once; nothing to process"
        )
    return d


def log_run_arrays(log, d=None, model_text: str = "") -> tuple[dict[str, np.ndarray], object]:
    """A recorder log as the arrays of an accelnav run file (and its model); what ``log export`` writes."""
    from accelnav.data.runfile import FORMAT
    from accelnav.link.manifest import sample_columns
    from accelnav.model.load import ModelError, loads_model

    if d is None:
        d = _decoded(log, model_text)
    cols = sample_columns(d.manifest, d.frames["sample"])
    text = d.meta.get("model_toml") or model_text
    if not text:
        raise UserError(
            f"{log}: the log carries no model text (recorded with --manifest): give --model M.toml, the model the "
            "firmware was built with (a run file needs it)"
        )
    try:
        model = loads_model(text, source=f"{log}:model_toml")
    except ModelError as exc:
        raise UserError(str(exc)) from None
    arrays = {
        "format": np.array(FORMAT),
        "model_toml": np.array(text),
        "model_source": np.array(f"{log}:model_toml"),
        **run_arrays(d.manifest, cols, model),
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
    from accelnav.link.decoder import decode_all, replay_for
    from accelnav.link.manifest import sample_columns

    frames, stats = decode_all(man, telemetry, replay_for(man, fitted))  # compact frames: the firmware's C replayed
    cols = sample_columns(man, frames["sample"])
    if stats.lost or len(cols["t"]) != len(run.t):
        raise UserError(f"telemetry: {len(cols['t'])} sample frames for {len(run.t)} samples, {stats.lost} lost")
    arrays = run_arrays(man, cols, fitted)
    for key in ("r", "u", "a", "eps"):
        arrays[key] = getattr(run, key)
    return arrays


def run_arrays(man, cols: dict[str, np.ndarray], model: Model) -> dict[str, np.ndarray]:
    """t, axis_names, accel (the model's conversion of the raw input), clipped (the firmware's skip flag),
    the raw fields (int32) and fw_x (n_axes, N, 4), from the sample columns of manifest ``man``."""
    names = list(man.axes)
    raw = man.raw_fields()
    skipped = (cols["axis_flags"] & (1 << man.axis_flags["skipped"])) != 0
    accel = np.empty((len(cols["t"]), len(names)))
    for j in range(len(names)):
        accel[:, j] = input_conversion(model, j).accel(*(cols[r][:, j] for r in raw))
    return {
        "t": cols["t"],
        "axis_names": np.array(names),
        "accel": accel,
        "clipped": skipped,
        **{r: cols[r].astype(np.int32) for r in raw},
        "fw_x": np.stack(
            [np.stack([cols[s][:, j] for s in ("r", "u", "a", "eps")], axis=1) for j in range(len(names))]
        ),
    }


def log_summary(path: str | Path, model_text: str = "") -> dict:
    """What ``accelnav log info`` prints: the log's header, its manifest and link counts, streamed."""
    from accelnav.link.accounting import format_counts, link_counts
    from accelnav.link.logfile import LogError
    from accelnav.link.recorder import decode_log

    try:
        d = decode_log(path, model_text, rows=False)  # streamed: memory does not grow with the log
    except LogError as exc:
        raise UserError(str(exc)) from None
    s = d.frames["sample"]
    man = d.manifest
    out = {
        "log": str(path),
        "source": d.meta.get("source"),
        "started_utc": d.meta.get("started_utc"),
        "model": man.data.get("model"),
        "model_sha256": man.model_sha256,
        "layout_hash": f"0x{man.layout_hash:08x}",
        "axes": man.axes,
        "input": man.input,
        "rate_hz": man.rate_hz,
        "chunks": d.chunks,
        "damaged_bytes": d.damaged_bytes,
        "torn_bytes": d.torn_bytes,
        **d.stats,
        **link_counts(d.stats),
        "counts": format_counts(link_counts(d.stats)),
        # two clocks, two different spans: the device's samples (index span at its rate: the recording's length)
        # and the host's arrivals (first to last chunk read; a device that buffered before the host read, or a
        # simulator faster than real time, makes it shorter, a stalled link longer)
        "device_seconds": float((s["index"][-1] - s["index"][0] + 1) / man.rate_hz) if len(s) else 0.0,
        "host_seconds": float((d.host_t_ns[-1] - d.host_t_ns[0]) / 1e9) if len(s) else 0.0,
        "index_first": int(s["index"][0]) if len(s) else None,
        "index_last": int(s["index"][-1]) if len(s) else None,
        "tx_drop_last": int(s["tx_drop"][-1]) if len(s) else None,
        "warnings": d.warnings,
    }
    if len(d.frames["info"]):
        info = d.frames["info"][-1]
        out["device_layout_ok"] = int(info["layout_hash"]) == man.layout_hash
        out["device_decimation"] = int(info["decimation"])
    return out
