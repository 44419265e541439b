"""The telemetry frame layout: defined here once, emitted as C for the firmware and as JSON for the host.

Wire format (both directions, every link)::

    frame   = COBS(payload || crc32_le(payload)) || 0x00
    payload = type:u8 || fields (little-endian, packed, no padding)

CRC-32 is the IEEE 802.3 / zlib one (reflected 0xEDB88320, init and final
xor 0xFFFFFFFF) over the payload; COBS removes every 0x00 so that a single
0x00 ends a frame and a receiver resynchronises at the next one after any
garbage. Every frame is shorter than 254 bytes, so its COBS form is exactly
one byte longer than ``payload || crc`` whatever the content: all frames of a
type have the same length on the wire, which the vectorised host decoder uses.

Frame types (MCU -> host):

* ``block`` (decimation 1, the compact mode, the default): the raw input of up to
  ``BLOCK_SAMPLES`` consecutive samples (ADC codes, or T1/T2 counts) and per
  sample and axis a 2-bit code (:data:`AXIS_CODES`: updated, input refused,
  no capture, sample missed by the board), after the 32-bit index of its
  first sample, the frame flags and the counters. ``n`` says how many of the
  slots are used (a partial block is sent on ``flush``, ``stop``, a mode
  change). The host gets the filter's states by running the firmware's own
  generated C on these inputs (accelnav.link.replay). Its ``run`` (the board's
  boot id plus one per reset, as in the checkpoints) tells a reset or a reboot
  from frames of an earlier run sent again.
* ``checkpoint`` (compact mode): one axis' state before the sample ``index``
  as its checkpoint image, the bytes the generated ``accelnav_AXIS_save``
  writes (the filter manifest's ``checkpoint.bytes``, checked by the
  firmware's build): the state struct's own bytes for the covariance form;
  for the gain schedule the same members with the schedule's row as its
  index in the table instead of a pointer, so that both ends read the same
  bytes (``checkpoint_rows`` in the manifest says where that index lies; one
  outside the table is refused as damaged). One per axis every
  ``CHECKPOINT_SAMPLES`` samples and whenever a compact run begins (flag
  ``resume``). The host's replay must match every one bit for bit; it starts
  from one after a gap. It also carries ``run``, ``paused_at`` (where the
  compact stream last paused: the host counts the samples sent before it that
  never came) and ``seq`` (the next sample frame's: the host counts the state
  mode's first frames when they are lost).
* ``sample`` (the state mode: decimation > 1, or any after ``mode_states``; one per decimated sample:
  sequence number, sample index, flags, counters, per axis the raw input and
  the filter state in the generated fixed-point formats), ``info`` (protocol version, layout
hash, model hash, rate, decimation), ``ack`` (answer to a command). Host -> MCU:
the commands ``start``, ``stop``, ``reset``, ``decimate``, ``info``,
``zupt_begin``, ``zupt_end``, ``flush``, ``mode_states``, ``mode_compact``, and
``stimulus`` (the raw input of one sample, used by the emulated and host
boards, which have no ADC).

The layout is derived from the model (axes, raw input kind) and from the
filter manifest that :func:`codegen.emit_c.emit` returns (the Q formats of r,
u, a, eps): :func:`layout` computes it, :func:`emit_frames` returns
``{"acnframe.h", "acnframe.c", "acnframe.json"}``; :func:`codegen.generated.generate`
returns them with the filter, and only the CLI (``accelnav codegen``) writes files.
"""

from __future__ import annotations

import json
import zlib
from dataclasses import dataclass

from accelnav.model.load import Model

from .package import banner, check_prefix

PROTOCOL_VERSION = 3  # 3: run ids, paused_at and seq in the compact frames
MAX_ENCODED = 254  # payload + crc must stay below this (one COBS block)

# name -> (bytes, numpy dtype, C type)
SCALARS = {
    "u8": (1, "<u1", "uint8_t"),
    "u16": (2, "<u2", "uint16_t"),
    "u32": (4, "<u4", "uint32_t"),
    "i32": (4, "<i4", "int32_t"),
    "i64": (8, "<i8", "int64_t"),
}

TYPE_SAMPLE, TYPE_INFO, TYPE_ACK, TYPE_BLOCK, TYPE_CHECKPOINT = 0x01, 0x02, 0x03, 0x04, 0x05
MAX_BLOCK = 32  # samples per block frame at most (fewer when they do not fit in one COBS block)
CHECKPOINT_EVERY = 256  # samples between checkpoints, rounded up to whole blocks
COMMANDS = {  # name -> (type, argument fields, meaning)
    "start": (0x10, (), "start streaming sample frames"),
    "stop": (0x11, (), "stop streaming (the filters keep running)"),
    "reset": (0x12, (), "re-initialise every axis filter and the sample index"),
    "decimate": (
        0x13,
        (("factor", "u16"),),
        "1: compact block and checkpoint frames; 2..1000: one sample frame in `factor` (others are refused)",
    ),
    "info": (0x14, (), "send an info frame"),
    "zupt_begin": (0x15, (), "mark the start of a zero-velocity interval"),
    "zupt_end": (0x16, (), "mark its end"),
    "flush": (0x17, (), "send the unfinished block and a checkpoint now (compact mode)"),
    "mode_states": (0x18, (), "at decimation 1 too, send sample frames with the filter's states (state mode)"),
    "mode_compact": (0x19, (), "at decimation 1, send block and checkpoint frames (the default)"),
}
TYPE_STIMULUS = 0x20
MAX_DECIMATION = 1000

# bits of the sample frame's `flags`
FLAGS = {
    "running": 0,  # streaming enabled (always set in sample frames)
    "zupt": 1,  # inside a host-marked zero-velocity interval
    "reset": 2,  # first frame after a filter reset
    "overflow": 3,  # a filter saturated since the previous frame
    "resume": 4,  # block, checkpoint: first of a compact run (after power-on, start, reset, decimate 1)
    # set by the host decoder only, on the sample rows it rebuilds from block frames
    "replayed": 5,  # the row's states come from the host's replay of the firmware's filter
    "mismatch": 6,  # the checkpoint closing the row's stretch differed from the replay
}
# bits of each axis' `flags`
AXIS_FLAGS = {
    "skipped": 0,  # update skipped: the input was on a rail / saturated, or the capture was invalid
    "rail": 1,  # analog: code at 0 or full scale
    "timeout": 2,  # duty cycle: no capture within two periods (sensor unplugged)
    "missed": 3,  # the board missed the sample (main loop too slow): predicted over, no input
}
# the 2-bit per-axis code of every sample in a block frame (bits 2i, 2i+1 of `aflags` for axis i)
AXIS_CODES = {"updated": 0, "refused": 1, "no_capture": 2, "missed": 3}
ACK_STATUS = {"ok": 0, "bad_argument": 1}
BOARDS = {
    "host": 1,
    "mps2_an385": 2,
    "stm32f103": 3,
    "microbit": 4,
    "stm32vldiscovery": 5,
    "sifive_e": 6,
    "atmega328p": 7,
    "arduino": 8,
    "netduino2": 9,
}


@dataclass(frozen=True)
class Field:
    name: str  # "seq", or "x.r" for axis x
    kind: str  # a key of SCALARS, or "T[N]" (N of a scalar T)
    offset: int
    c_expr: str  # member of the C struct this field packs from / unpacks to
    unit: str = ""
    frac: int = 0  # fixed-point fractional bits (value = int * 2**-frac)
    doc: str = ""

    @property
    def scalar(self) -> str:
        return self.kind.split("[")[0]

    @property
    def count(self) -> int:
        """Elements: 1 for a scalar, N for "T[N]"."""
        return int(self.kind[self.kind.index("[") + 1 : -1]) if "[" in self.kind else 1

    @property
    def size(self) -> int:
        return self.count * SCALARS[self.scalar][0]

    @property
    def dtype(self) -> str:
        if "[" in self.kind:
            return f"({self.count},){SCALARS[self.scalar][1]}"
        return SCALARS[self.kind][1]


@dataclass(frozen=True)
class Frame:
    name: str
    type: int
    direction: str  # "up" (MCU -> host) or "down"
    fields: tuple[Field, ...]
    ctype: str  # the C struct

    @property
    def size(self) -> int:
        """Payload bytes, type byte included, CRC excluded."""
        return 1 + sum(f.size for f in self.fields)

    def field(self, name: str) -> Field:
        for f in self.fields:
            if f.name == name:
                return f
        raise KeyError(f"{self.name}.{name}")

    @property
    def wire_size(self) -> int:
        """Bytes on the wire: COBS overhead byte, payload, CRC, delimiter."""
        return self.size + 4 + 2


class _Builder:
    def __init__(self, prefix: str):
        self.fields: list[Field] = []
        self.offset = 1  # after the type byte
        self.prefix = prefix

    def add(self, name: str, kind: str, c_expr: str, **meta) -> None:
        f = Field(name, kind, self.offset, c_expr, **meta)
        self.fields.append(f)
        self.offset += f.size


def _add_counters(b: _Builder) -> None:
    """The board's health counters, the same in the sample and the block frames."""
    b.add("tx_drop", "u16", "s->tx_drop", doc="frames the MCU could not queue (link too slow), mod 2^16")
    b.add("skipped", "u16", "s->skipped", doc="updates skipped (rail, bad capture, timeout), mod 2^16")
    b.add("overflow", "u16", "s->overflow", doc="filter saturations, all axes, saturating at 65535")
    b.add("missed", "u16", "s->missed", doc="samples the board missed (main loop too slow), predicted over, mod 2^16")
    b.add("rx_lost", "u16", "s->rx_lost", doc="bytes the board's receivers lost (overrun, full ring), mod 2^16")


def _state_formats(filter_manifest: dict) -> list[dict[str, tuple[int, int, str]]]:
    """Per axis {state: (word, frac, unit)} of what `accelnav_AXIS_read` returns."""
    out = []
    for ax in filter_manifest["axes"]:
        v = ax["variables"]
        out.append(
            {
                s: (v[k]["word"], v[k]["frac"], v[k]["unit"])
                for s, k in (("r", "r"), ("u", "u_out"), ("a", "a"), ("e", "e"))
            }
        )
    return out


@dataclass(frozen=True)
class Layout:
    model_name: str
    model_sha256: str
    rate_hz: float
    input: str  # "analog" or "duty_cycle"
    axes: tuple[str, ...]
    full_code: int  # analog: the rail code; duty: 0
    t2_nominal: int  # duty: nominal period in counts; analog: 0
    timer_hz: int  # duty: capture timer clock; analog: 0
    frames: tuple[Frame, ...]
    block_samples: int  # sample slots of a block frame
    checkpoint_samples: int  # samples between checkpoints (whole blocks)
    state_bytes: tuple[int, ...]  # per axis: bytes of the state's checkpoint image (accelnav_AXIS_save)
    compact: bool  # False when a filter has no checkpoint image (the float32 variant): no compact mode
    # per axis: (offset, rows) of the gain schedule's row index in the image, None for the covariance form
    checkpoint_rows: tuple[tuple[int, int] | None, ...] = ()

    def sent(self, f: Frame) -> bool:
        """Whether frame ``f`` is part of the protocol (block and checkpoint only with the compact mode)."""
        return self.compact or f.name not in ("block", "checkpoint")

    def _rows_json(self) -> list[dict | None]:
        """Per axis where the gain schedule's row index lies in a checkpoint image: offset (u32,
        little-endian) and rows (an index must be below it), or None."""
        return [None if r is None else {"offset": r[0], "rows": r[1]} for r in self.checkpoint_rows]

    def frame(self, name: str) -> Frame:
        for f in self.frames:
            if f.name == name:
                return f
        raise KeyError(name)

    def definition(self) -> dict:
        """Everything the two ends must agree on, as plain data (hashed into the layout hash)."""
        return {
            "protocol_version": PROTOCOL_VERSION,
            "input": self.input,
            "axes": list(self.axes),
            "flags": FLAGS,
            "axis_flags": AXIS_FLAGS,
            "axis_codes": AXIS_CODES,
            "block_samples": self.block_samples,
            "checkpoint_samples": self.checkpoint_samples,
            "state_bytes": list(self.state_bytes),
            # only with a gain-schedule axis (a covariance build's layout and hash stay as they were)
            **({"checkpoint_rows": self._rows_json()} if any(r is not None for r in self.checkpoint_rows) else {}),
            "frames": {
                f.name: {
                    "type": f.type,
                    "direction": f.direction,
                    "size": f.size,
                    "wire_size": f.wire_size,
                    "fields": [
                        {
                            "name": x.name,
                            "kind": x.kind,
                            "dtype": x.dtype,
                            "offset": x.offset,
                            "unit": x.unit,
                            "frac": x.frac,
                        }
                        for x in f.fields
                    ],
                }
                for f in self.frames
                if self.sent(f)
            },
        }

    @property
    def layout_hash(self) -> int:
        text = json.dumps(self.definition(), sort_keys=True, separators=(",", ":"))
        return zlib.crc32(text.encode())

    def manifest(self) -> dict:
        d = self.definition()
        d.update(
            {
                "protocol": "accelnav-telemetry",
                "layout_hash": self.layout_hash,
                "model": self.model_name,
                "model_sha256": self.model_sha256,
                "sample_rate_hz": self.rate_hz,
                "full_code": self.full_code,
                "t2_nominal": self.t2_nominal,
                "framing": {"cobs": True, "delimiter": 0, "crc": "crc32-ieee-le", "crc_bytes": 4},
                "ack_status": ACK_STATUS,
                "boards": BOARDS,
                "max_decimation": MAX_DECIMATION,
                "commands": {k: v[2] for k, v in COMMANDS.items()},
            }
        )
        return d


def _sample_frame(names: tuple[str, ...], fmts, duty: bool) -> Frame:
    """The state mode's sample frame: counters, then per axis its flags, raw input and states."""
    b = _Builder("s")
    b.add("seq", "u16", "s->seq", doc="sample frames sent since start, mod 2^16 (gaps = lost frames)")
    b.add("index", "u32", "s->index", doc="sample index since reset")
    b.add("flags", "u16", "s->flags", doc="FLAGS bits")
    _add_counters(b)
    for i, ax in enumerate(names):
        a = f"s->axis[{i}]"
        b.add(f"{ax}.flags", "u8", f"{a}.flags", doc="AXIS_FLAGS bits")
        if duty:
            b.add(f"{ax}.t1", "u32", f"{a}.t1", unit="count", doc="high time")
            b.add(f"{ax}.t2", "u32", f"{a}.t2", unit="count", doc="period")
        else:
            b.add(f"{ax}.code", "u16", f"{a}.code", unit="LSB", doc="ADC code")
        for s in ("r", "u", "a", "e"):
            word, frac, unit = fmts[i][s]
            b.add(f"{ax}.{s}", f"i{word}", f"{a}.{s}", unit=unit, frac=frac)
    return Frame("sample", TYPE_SAMPLE, "up", tuple(b.fields), "sample_t")


def _fixed_frames() -> list[Frame]:
    """The frames that do not depend on the model: info, ack and the commands."""
    frames = []
    b = _Builder("s")
    b.add("protocol", "u16", "s->protocol")
    b.add("layout_hash", "u32", "s->layout_hash")
    b.add("runtime_api", "u16", "s->runtime_api")
    b.add("board", "u8", "s->board")
    b.add("running", "u8", "s->running")
    b.add("decimation", "u16", "s->decimation")
    b.add("rate_mhz", "u32", "s->rate_mhz", unit="mHz")
    b.add("index", "u32", "s->index")
    b.add("seq", "u16", "s->seq", doc="seq of the next sample frame")
    b.add("uptime_ms", "u32", "s->uptime_ms", unit="ms", doc="board time base")
    b.add("rx_errors", "u16", "s->rx_errors", doc="received frames refused (CRC, COBS, type, size), mod 2^16")
    b.add("model_sha256", "u8[32]", "s->model_sha256")
    frames.append(Frame("info", TYPE_INFO, "up", tuple(b.fields), "info_t"))

    b = _Builder("s")
    b.add("command", "u8", "s->command")
    b.add("status", "u8", "s->status")
    b.add("arg", "u16", "s->arg")
    b.add("index", "u32", "s->index")
    frames.append(Frame("ack", TYPE_ACK, "up", tuple(b.fields), "ack_t"))

    for name, (code, args, _doc) in COMMANDS.items():
        b = _Builder("c")
        for an, kind in args:
            b.add(an, kind, f"c->{an}")
        frames.append(Frame(f"cmd_{name}", code, "down", tuple(b.fields), "command_t"))
    return frames


def _stimulus_frame(names: tuple[str, ...], duty: bool) -> Frame:
    """The raw input of one sample, host to board (the emulated and host boards have no ADC)."""
    b = _Builder("t")
    b.add("flags", "u8", "t->flags", doc="bit i: axis i has no capture (duty cycle timeout)")
    for i, ax in enumerate(names):
        if duty:
            b.add(f"{ax}.t1", "u32", f"t->t1[{i}]", unit="count")
            b.add(f"{ax}.t2", "u32", f"t->t2[{i}]", unit="count")
        else:
            b.add(f"{ax}.code", "u16", f"t->code[{i}]", unit="LSB")
    return Frame("stimulus", TYPE_STIMULUS, "down", tuple(b.fields), "stimulus_t")


def layout(model: Model, filter_manifest: dict) -> Layout:
    """The frame layout of ``model`` with the state formats of its generated filter."""
    from .ranges import refuse_calibrated

    refuse_calibrated(model)
    names = tuple(a.name for a in model.axes)
    if [a["axis"] for a in filter_manifest["axes"]] != list(names):
        raise ValueError("the filter manifest's axes differ from the model's: regenerate the filter")
    fmts = _state_formats(filter_manifest)
    duty = model.sensor.kind == "duty_cycle"
    frames = []

    frames.append(_sample_frame(names, fmts, duty))

    # compact mode: raw inputs of a block of samples; the host replays the filter (see the module docstring).
    # A checkpoint carries the state's image (accelnav_AXIS_save: the gain schedule's row as an index, not a
    # pointer); a filter without one (float32) streams sample frames only (ACNF_COMPACT 0; the block and
    # checkpoint frames stay out of the manifest)
    cks = [ax.get("checkpoint") or {} for ax in filter_manifest["axes"]]
    state_bytes = [ck.get("bytes") for ck in cks]
    compact = all(isinstance(nb, int) and nb > 0 for nb in state_bytes)
    rows = tuple(None if ck.get("row") is None else (int(ck["row"]["offset"]), int(ck["row"]["rows"])) for ck in cks)
    if not compact:
        state_bytes = [1] * len(names)
        rows = (None,) * len(names)
    if duty:
        # the generated convert refuses periods more than 25 % off the nominal one: with 1.5 x nominal
        # below 2^16 every count it accepts fits a u16 (a larger one is sent as 65535 and is refused too)
        raw_kind = "u16" if model.sensor.duty_cycle.t2_counts * 3 // 2 < 0xFFFF else "u32"
        raw_keys = ("t1", "t2")
    else:
        if model.sensor.analog.adc_bits > 16:
            raise ValueError(f"adc_bits {model.sensor.analog.adc_bits}: block frames carry codes of at most 16 bits")
        raw_kind, raw_keys = "u16", ("code",)
    per_sample = (1 if len(names) <= 4 else 2) + len(names) * len(raw_keys) * SCALARS[raw_kind][0]
    head = 1 + 4 + 1 + 1 + 2 + 5 * 2
    nblk = min(MAX_BLOCK, (MAX_ENCODED - 1 - 4 - head) // per_sample)
    b = _Builder("s")
    b.add("index", "u32", "s->index", doc="index of the block's first sample")
    b.add("flags", "u8", "s->flags", doc="FLAGS bits")
    b.add("n", "u8", "s->n", doc="slots in use (the others are zero)")
    b.add("run", "u16", "s->run", doc="run id: the board's boot id, plus one per reset command, mod 2^16")
    _add_counters(b)
    b.add("aflags", f"{'u8' if len(names) <= 4 else 'u16'}[{nblk}]", "s->aflags", doc="AXIS_CODES, 2 bits per axis")
    for i, ax in enumerate(names):
        for k in raw_keys:
            b.add(f"{ax}.{k}", f"{raw_kind}[{nblk}]", f"s->{k}[{i}]", unit="count" if duty else "LSB")
    frames.append(Frame("block", TYPE_BLOCK, "up", tuple(b.fields), "block_t"))
    b = _Builder("s")
    b.add("index", "u32", "s->index", doc="the state before this sample")
    b.add("flags", "u8", "s->flags", doc="FLAGS bits")
    b.add("axis", "u8", "s->axis", doc="axis number")
    b.add("run", "u16", "s->run", doc="run id, as in the block frames")
    b.add("paused_at", "u32", "s->paused_at", doc="index where the compact stream last paused (0 after a reset)")
    b.add("seq", "u16", "s->seq", doc="seq the next sample frame will carry (state mode)")
    b.add("state", f"u8[{max(state_bytes)}]", "s->state", doc="the axis' checkpoint image (zero padded)")
    frames.append(Frame("checkpoint", TYPE_CHECKPOINT, "up", tuple(b.fields), "checkpoint_t"))
    frames += _fixed_frames()
    frames.append(_stimulus_frame(names, duty))

    for f in frames:
        if f.size + 4 >= MAX_ENCODED:
            raise ValueError(f"frame {f.name} is {f.size + 4} bytes with its CRC; at most {MAX_ENCODED - 1} fit")
    if duty:
        full_code, t2n, timer_hz = 0, model.sensor.duty_cycle.t2_counts, round(model.sensor.duty_cycle.timer_clock_hz)
    else:
        full_code, t2n, timer_hz = 2**model.sensor.analog.adc_bits - 1, 0, 0
    return Layout(
        model.name,
        model.sha256,
        model.rate_hz,
        model.sensor.kind,
        names,
        full_code,
        t2n,
        timer_hz,
        tuple(frames),
        nblk,
        nblk * -(-CHECKPOINT_EVERY // nblk),
        tuple(state_bytes),
        compact,
        rows,
    )


# --------------------------------------------------------------------------
# C emitter


def _banner(lay: Layout, what: str) -> str:
    by = f"accelnav codegen.frames (protocol {PROTOCOL_VERSION}, layout 0x{lay.layout_hash:08x})"
    return banner(what, by, lay.model_name, lay.model_sha256)


def _put(f: Field) -> str:
    if f.kind.startswith("u8["):
        return f"    memcpy(p + {f.offset}, {f.c_expr}, {f.size}); /* {f.name} */"
    bits = SCALARS[f.scalar][0] * 8
    if f.count > 1:
        return (
            f"    for (k = 0; k < {f.count}u; ++k) {{ /* {f.name} {f.kind}{_qnote(f)} */\n"
            f"        acnf_put{bits}(p + {f.offset}u + {bits // 8}u * k, {f.c_expr}[k]);\n"
            "    }"
        )
    cast = f"(uint{bits}_t)" if f.kind.startswith("i") else ""
    return f"    acnf_put{bits}(p + {f.offset}, {cast}{f.c_expr}); /* {f.name} {f.kind}{_qnote(f)} */"


def _get(f: Field) -> str:
    bits = SCALARS[f.kind][0] * 8
    return f"    {f.c_expr} = (uint{bits}_t)acnf_get{bits}(p + {f.offset}); /* {f.name} */"


def _qnote(f: Field) -> str:
    return f" [{f.unit}] Q.{f.frac}" if f.frac else (f" [{f.unit}]" if f.unit else "")


def emit_frames(model: Model, filter_manifest: dict, prefix: str = "acnframe") -> dict[str, str]:
    """``{prefix}.h``, ``{prefix}.c`` (packers, strict unpackers) and ``{prefix}.json`` (the host's manifest)."""
    check_prefix(prefix)
    lay = layout(model, filter_manifest)
    duty = lay.input == "duty_cycle"
    n = len(lay.axes)
    sample, info, ack = lay.frame("sample"), lay.frame("info"), lay.frame("ack")
    block, ckpt = lay.frame("block"), lay.frame("checkpoint")
    raw_f = block.fields[-1]
    raw_t = f"uint{SCALARS[raw_f.scalar][0] * 8}_t"
    aflags_t = f"uint{SCALARS[block.field('aflags').scalar][0] * 8}_t"
    stim = lay.frame("stimulus")
    max_up = max(f.size for f in lay.frames if f.direction == "up")  # block and checkpoint included
    max_down = max(f.size for f in lay.frames if f.direction == "down")
    period_us = round(1e6 / lay.rate_hz)
    H = [
        _banner(lay, f"{prefix}.h: telemetry frame layout, packers and parsers"),
        "#ifndef ACNFRAME_H",
        "#define ACNFRAME_H",
        "",
    ]
    H += ["#include <stdbool.h>", "#include <stddef.h>", "#include <stdint.h>", ""]
    H += [
        f"#define ACNF_PROTOCOL_VERSION {PROTOCOL_VERSION}u",
        f"#define ACNF_LAYOUT_HASH UINT32_C(0x{lay.layout_hash:08x})",
        f"#define ACNF_NAXES {n}",
        f"#define ACNF_INPUT_DUTY {int(duty)} /* 0: ADC code per axis, 1: T1/T2 capture counts */",
        f"#define ACNF_FULL_CODE {lay.full_code} /* analog: codes 0 and this are rails */",
        f"#define ACNF_T2_NOMINAL UINT32_C({lay.t2_nominal}) /* duty: nominal period, counts */",
        f"#define ACNF_TIMER_HZ UINT32_C({lay.timer_hz}) /* duty: capture timer clock, Hz */",
        f"#define ACNF_RATE_MHZ UINT32_C({round(lay.rate_hz * 1000)}) /* sample rate, mHz */",
        f"#define ACNF_PERIOD_US UINT32_C({period_us}) /* sample period, us (rounded) */",
        f"#define ACNF_MAX_DECIMATION {MAX_DECIMATION}u",
        "#define ACNF_MODEL_SHA256_BYTES {" + ", ".join(f"0x{b:02x}u" for b in bytes.fromhex(lay.model_sha256)) + "}",
        "/* X-macro over the axes: M(name, NAME, index) (a parameter no axis name can be: axis x is X) */",
        "#define ACNF_AXES(ACNF_AXIS_M) "
        + " ".join(f"ACNF_AXIS_M({a}, {a.upper()}, {i})" for i, a in enumerate(lay.axes)),
        "",
        "/* frame types */",
        f"#define ACNF_T_SAMPLE 0x{TYPE_SAMPLE:02x}u",
        f"#define ACNF_T_INFO 0x{TYPE_INFO:02x}u",
        f"#define ACNF_T_ACK 0x{TYPE_ACK:02x}u",
        f"#define ACNF_T_BLOCK 0x{TYPE_BLOCK:02x}u",
        f"#define ACNF_T_CHECKPOINT 0x{TYPE_CHECKPOINT:02x}u",
    ]
    H += [f"#define ACNF_CMD_{k.upper()} 0x{v[0]:02x}u /* {v[2]} */" for k, v in COMMANDS.items()]
    H += [f"#define ACNF_T_STIMULUS 0x{TYPE_STIMULUS:02x}u", ""]
    H += [f"#define ACNF_FLAG_{k.upper()} (1u << {v})" for k, v in FLAGS.items()]
    H += [f"#define ACNF_AXIS_{k.upper()} (1u << {v})" for k, v in AXIS_FLAGS.items()]
    H += [f"#define ACNF_CODE_{k.upper()} {v}u /* block: 2-bit per-axis code */" for k, v in AXIS_CODES.items()]
    H += [f"#define ACNF_ACK_{k.upper()} {v}u" for k, v in ACK_STATUS.items()]
    H += [f"#define ACNF_BOARD_{k.upper()} {v}u" for k, v in BOARDS.items()]
    H += [
        "",
        "/* payload sizes (type byte included, CRC excluded) */",
        f"#define ACNF_SAMPLE_SIZE {sample.size}u",
        f"#define ACNF_INFO_SIZE {info.size}u",
        f"#define ACNF_ACK_SIZE {ack.size}u",
        f"#define ACNF_STIMULUS_SIZE {stim.size}u",
        f"#define ACNF_BLOCK_SIZE {block.size}u",
        f"#define ACNF_CHECKPOINT_SIZE {ckpt.size}u",
        "",
        "/* compact mode */",
        f"#define ACNF_COMPACT {int(lay.compact)} /* 0: no compact mode (a filter without a checkpoint image) */",
        f"#define ACNF_BLOCK_SAMPLES {lay.block_samples}u /* sample slots of a block frame */",
        f"#define ACNF_CHECKPOINT_SAMPLES {lay.checkpoint_samples}u /* samples between checkpoints */",
        f"#define ACNF_STATE_BYTES {max(lay.state_bytes)}u /* the largest axis checkpoint image */",
        f"#define ACNF_RAW_MAX {2 ** (8 * SCALARS[raw_f.scalar][0]) - 1}u /* block: larger inputs are sent as this */",
        *[
            f"#define ACNF_STATE_BYTES_{i} {nb}u /* axis {a}'s checkpoint image (accelnav_{a}_save) */"
            for i, (a, nb) in enumerate(zip(lay.axes, lay.state_bytes, strict=True))
        ],
        f"#define ACNF_MAX_UP_SIZE {max_up}u",
        f"#define ACNF_MAX_DOWN_SIZE {max_down}u",
        "/* bytes on the wire: COBS code byte + payload + CRC-32 + delimiter */",
        f"#define ACNF_MAX_UP_WIRE {max_up + 6}u",
        f"#define ACNF_MAX_DOWN_WIRE {max_down + 6}u",
        "",
        "typedef struct {",
        "    uint8_t flags; /* ACNF_AXIS_* */",
    ]
    if duty:
        H += ["    uint32_t t1; /* high time [count] */", "    uint32_t t2; /* period [count] */"]
    else:
        H += ["    uint16_t code; /* ADC code [LSB] */"]
    fm = _state_formats(filter_manifest)[0]
    same = all(_state_formats(filter_manifest)[i] == fm for i in range(n))
    for s, doc in (("r", "position"), ("u", "velocity"), ("a", "acceleration"), ("e", "bias")):
        word, frac, unit = fm[s]
        note = f"Q.{frac}" if same else "Q per axis: see the manifest"
        H.append(f"    int{word}_t {s}; /* {doc} [{unit}] {note} */")
    H += ["} acnf_axis_t;", ""]
    H += [
        "typedef struct {",
        "    uint16_t seq;",
        "    uint32_t index;",
        "    uint16_t flags; /* ACNF_FLAG_* */",
        "    uint16_t tx_drop;",
        "    uint16_t skipped;",
        "    uint16_t overflow;",
        "    uint16_t missed;",
        "    uint16_t rx_lost;",
        "    acnf_axis_t axis[ACNF_NAXES];",
        "} acnf_sample_t;",
        "",
        "typedef struct {",
        "    uint16_t protocol;",
        "    uint32_t layout_hash;",
        "    uint16_t runtime_api;",
        "    uint8_t board;",
        "    uint8_t running;",
        "    uint16_t decimation;",
        "    uint32_t rate_mhz;",
        "    uint32_t index;",
        "    uint16_t seq;",
        "    uint32_t uptime_ms;",
        "    uint16_t rx_errors;",
        "    uint8_t model_sha256[32];",
        "} acnf_info_t;",
        "",
        f"typedef {aflags_t} acnf_aflags_t; /* a block's per-sample axis codes */",
        "",
        "typedef struct {",
        "    uint32_t index; /* first sample */",
        "    uint8_t flags; /* ACNF_FLAG_* */",
        "    uint8_t n; /* slots in use */",
        "    uint16_t run; /* boot id + resets */",
        "    uint16_t tx_drop;",
        "    uint16_t skipped;",
        "    uint16_t overflow;",
        "    uint16_t missed;",
        "    uint16_t rx_lost;",
        "    acnf_aflags_t aflags[ACNF_BLOCK_SAMPLES]; /* ACNF_CODE_* of axis i in bits 2i, 2i+1 */",
        *(
            [f"    {raw_t} t1[ACNF_NAXES][ACNF_BLOCK_SAMPLES];", f"    {raw_t} t2[ACNF_NAXES][ACNF_BLOCK_SAMPLES];"]
            if duty
            else [f"    {raw_t} code[ACNF_NAXES][ACNF_BLOCK_SAMPLES];"]
        ),
        "} acnf_block_t;",
        "",
        "typedef struct {",
        "    uint32_t index; /* the state before this sample */",
        "    uint8_t flags; /* ACNF_FLAG_* */",
        "    uint8_t axis;",
        "    uint16_t run; /* boot id + resets */",
        "    uint32_t paused_at; /* index where the compact stream last paused */",
        "    uint16_t seq; /* seq of the next sample frame */",
        "    uint8_t state[ACNF_STATE_BYTES]; /* the axis' checkpoint image, zero padded */",
        "} acnf_checkpoint_t;",
        "",
        "typedef struct {",
        "    uint8_t command;",
        "    uint8_t status; /* ACNF_ACK_* */",
        "    uint16_t arg;",
        "    uint32_t index;",
        "} acnf_ack_t;",
        "",
        "typedef struct {",
        "    uint8_t type; /* ACNF_CMD_* */",
        "    uint16_t factor; /* decimate only */",
        "} acnf_command_t;",
        "",
        "typedef struct {",
        "    uint8_t flags; /* bit i: axis i has no capture */",
    ]
    if duty:
        H += ["    uint32_t t1[ACNF_NAXES];", "    uint32_t t2[ACNF_NAXES];"]
    else:
        H += ["    uint16_t code[ACNF_NAXES];"]
    H += [
        "} acnf_stimulus_t;",
        "",
        "/* Packers write the payload (type byte first) into p and return its size. */",
        "size_t acnf_pack_sample(const acnf_sample_t *s, uint8_t *p);",
        "size_t acnf_pack_info(const acnf_info_t *s, uint8_t *p);",
        "size_t acnf_pack_ack(const acnf_ack_t *s, uint8_t *p);",
        "size_t acnf_pack_block(const acnf_block_t *s, uint8_t *p);",
        "size_t acnf_pack_checkpoint(const acnf_checkpoint_t *s, uint8_t *p);",
        "/* Parsers accept a payload only with a known type and its exact size. */",
        "bool acnf_parse_command(const uint8_t *p, size_t n, acnf_command_t *c);",
        "bool acnf_parse_stimulus(const uint8_t *p, size_t n, acnf_stimulus_t *t);",
        "",
        "#endif",
        "",
    ]

    C = [_banner(lay, f"{prefix}.c: frame packers and parsers (little-endian, packed)"), f'#include "{prefix}.h"', ""]
    C += ["#include <string.h>", ""]
    C += [
        "static void acnf_put8(uint8_t *p, uint8_t v)",
        "{",
        "    p[0] = v;",
        "}",
        "",
        "static void acnf_put16(uint8_t *p, uint16_t v)",
        "{",
        "    p[0] = (uint8_t)v;",
        "    p[1] = (uint8_t)(v >> 8);",
        "}",
        "",
        "static void acnf_put32(uint8_t *p, uint32_t v)",
        "{",
        "    acnf_put16(p, (uint16_t)v);",
        "    acnf_put16(p + 2, (uint16_t)(v >> 16));",
        "}",
        "",
        "static void acnf_put64(uint8_t *p, uint64_t v)",
        "{",
        "    acnf_put32(p, (uint32_t)v);",
        "    acnf_put32(p + 4, (uint32_t)(v >> 32));",
        "}",
        "",
        "static uint16_t acnf_get16(const uint8_t *p)",
        "{",
        "    return (uint16_t)(p[0] | (uint16_t)p[1] << 8);",
        "}",
        "",
    ]
    if any(f.kind == "u32" for fr in lay.frames if fr.direction == "down" for f in fr.fields):
        C += [
            "static uint32_t acnf_get32(const uint8_t *p)",
            "{",
            "    return (uint32_t)acnf_get16(p) | (uint32_t)acnf_get16(p + 2) << 16;",
            "}",
            "",
        ]
    for fr, arg in (
        (sample, "acnf_sample_t"),
        (info, "acnf_info_t"),
        (ack, "acnf_ack_t"),
        (block, "acnf_block_t"),
        (ckpt, "acnf_checkpoint_t"),
    ):
        C += [f"size_t acnf_pack_{fr.name}(const {arg} *s, uint8_t *p)", "{"]
        if any(f.count > 1 and not f.kind.startswith("u8[") for f in fr.fields):
            C += ["    size_t k;"]
        C += [f"    p[0] = ACNF_T_{fr.name.upper()};"]
        C += [_put(f) for f in fr.fields]
        C += [f"    return {fr.size}u;", "}", ""]
    C += [
        "bool acnf_parse_command(const uint8_t *p, size_t n, acnf_command_t *c)",
        "{",
        "    if (n < 1u) {",
        "        return false;",
        "    }",
        "    c->type = p[0];",
        "    c->factor = 0;",
        "    switch (p[0]) {",
    ]
    for name in COMMANDS:
        fr = lay.frame(f"cmd_{name}")
        C += [
            f"    case ACNF_CMD_{name.upper()}:",
            f"        if (n != {fr.size}u) {{",
            "            return false;",
            "        }",
        ]
        C += ["    " + _get(f) for f in fr.fields]
        C += ["        return true;"]
    C += ["    default:", "        return false;", "    }", "}", ""]
    C += [
        "bool acnf_parse_stimulus(const uint8_t *p, size_t n, acnf_stimulus_t *t)",
        "{",
        "    if (n != ACNF_STIMULUS_SIZE || p[0] != ACNF_T_STIMULUS) {",
        "        return false;",
        "    }",
        f"    t->flags = p[{stim.fields[0].offset}];",
    ]
    C += [_get(f) for f in stim.fields[1:]]
    C += ["    return true;", "}", ""]

    man = lay.manifest()
    return {
        f"{prefix}.h": "\n".join(H),
        f"{prefix}.c": "\n".join(C),
        f"{prefix}.json": json.dumps(man, indent=1, sort_keys=True) + "\n",
    }
