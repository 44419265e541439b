"""Software- and processor-in-the-loop runs of the firmware on simulated sensor data.

* SIL: the firmware's input stage, generated filter and frame packer (host
  board), in-process through cffi (:mod:`hil_sim.firmware`), fed the
  simulator's raw ADC codes or T1/T2 counts as stimulus frames.
* PIL: the same sources built for an emulated board and run in QEMU
  (:mod:`hil_sim.qemu`): mps2-an385 (Cortex-M3), microbit (Cortex-M0),
  stm32vldiscovery (the STM32 port's code on an STM32F100) or sifive_e
  (SiFive FE310, RV32IMAC, in qemu-system-riscv32), or in simavr
  (:mod:`hil_sim.simavr`): atmega328p (8-bit AVR, its one UART fed
  from a file by a libsimavr program, firmware/boards/atmega328p/simavr_feed.c). By
  default (``link="feed"``) the stimulus goes in and the telemetry comes out
  through files over semihosting, a block per trap (:func:`hil_sim.qemu.run_feed`),
  and the telemetry is written to the recorder's log format
  (:class:`accelnav.link.logfile.LogWriter`) and read back from it. With
  ``link="uart"`` the stimulus goes into the board's stimulus UART and its
  telemetry UART is recorded through the very same path as ``accelnav
  record`` (:class:`accelnav.link.recorder.Recorder` over a pyserial
  ``socket://`` port): the real link, slower, kept for the benchmark and one
  test.

The ADC boards (:data:`hil_sim.qemu.ADC_MACHINES`: netduino2) take no stimulus:
QEMU's ADC model makes the values. :func:`run_adc_pil` runs one for a number of
sample periods, takes the codes the firmware read from its ADC out of its own
telemetry, runs SIL on those codes, and compares the two telemetry streams byte
for byte.

:func:`compare` puts the frames side by side: PIL against SIL bit for bit,
frame by frame; both against the float64 reference (accelnav.estimate.kf) on the same
raw input, in units of the reference's own standard deviation; and truth
against the firmware's filter, the reference filter and the smoother.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.estimate.kf import rts_smooth, run_filter
from accelnav.estimate.pipeline import PositionErrors, error_rows, format_errors, smooth_run
from accelnav.estimate.zupt import rest_mask
from accelnav.fileio import Output
from accelnav.hil_sim.sim.sensor import SimRun
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.decoder import Decoder, decode_all, replay_for
from accelnav.link.manifest import Manifest, sample_columns
from accelnav.model.design import axis_design
from accelnav.model.load import G0, Model

from . import simavr
from .firmware import HostFirmware, build_firmware, manifest, private_firmware
from .qemu import MACHINES, QemuBoard, QemuError, machine_for, run_adc, run_feed

STATES = ("r", "u", "a", "eps")
PIL_BOARDS = (*MACHINES, *simavr.BOARDS)  # the boards `accelnav hil --target pil --board` runs


@dataclass(frozen=True, eq=False)
class RecordedRun:
    """A user's recording as the firmware's input: the raw samples the firmware would have read (``code``, or
    ``t1``/``t2``), their conversion ``accel`` [m/s^2] and ``clipped`` verdict, as in a SimRun; no truth
    (``r`` is None), so a comparison has no position-error rows."""

    source: str
    t: np.ndarray
    axis_names: tuple[str, ...]
    code: np.ndarray | None
    t1: np.ndarray | None
    t2: np.ndarray | None
    clipped: np.ndarray
    accel: np.ndarray
    r: None = None

    def to_arrays(self) -> dict[str, np.ndarray]:
        return {"t": self.t, "axis_names": np.array(self.axis_names), "accel": self.accel, "clipped": self.clipped}


def recorded_input(source, model: Model | None = None, **opts) -> tuple[RecordedRun, Model]:
    """Read a recording (any form :func:`accelnav.data.inputs.read_input` takes, ``opts`` its keywords) and
    turn it into the firmware's raw input for ``model``.

    Raw counts (``unit="counts"``, or an analog model's default) come back as the very codes of the file: the
    reader converts them with the model's own read-out, and the read-out of that acceleration is the code
    again. An acceleration in g or m/s^2 is read out as the sensor would have: rounded to the ADC's step (a
    duty-cycle part: T1 over the nominal T2), railed at the ends. Refusals raise UserError in one line."""
    from accelnav.data.inputs import read_input
    from accelnav.hil_sim.sim.sensor import read_out
    from accelnav.model.design import input_conversion

    run, model = read_input(source, model, **opts)
    model = _on_file(model)
    kind = model.sensor.kind
    if kind == "calibrated":
        raise UserError(
            f"{model.source}: a calibrated (digital) part; the firmware runs on an ADC or a timer's raw samples "
            "(sensor.kind analog or duty_cycle)"
        )
    accel = np.asarray(run["accel"], dtype=np.float64)
    n, n_axes = accel.shape
    raw = []
    for j in range(n_axes):
        if kind == "analog":
            raw.append(read_out(model, j, accel[:, j], None))
        else:  # no jitter: T2 at its nominal count, T1 the duty of the acceleration
            ax, t2 = model.axis(j), model.sensor.duty_cycle.t2_counts
            duty = np.clip(ax.zero_g + ax.sensitivity * accel[:, j] / G0, 0.0, 1.0)
            raw.append((np.rint(duty * t2).astype(np.int32), np.full(n, t2, dtype=np.int32)))
    convs = [input_conversion(model, j) for j in range(n_axes)]
    # what the firmware will see: the conversion of these raw samples, and its own verdict on them
    z = np.column_stack([c.accel(*r) for c, r in zip(convs, raw, strict=True)])
    clipped = np.column_stack([c.clipped(*r) for c, r in zip(convs, raw, strict=True)])

    def col(k: int) -> np.ndarray:
        return np.column_stack([r[k] for r in raw]).astype(np.int32)

    analog = kind == "analog"
    rec = RecordedRun(
        source=str(source),
        t=np.asarray(run["t"], dtype=np.float64),
        axis_names=tuple(str(a) for a in run["axis_names"]),
        code=col(0) if analog else None,
        t1=None if analog else col(0),
        t2=None if analog else col(1),
        clipped=clipped,
        accel=z,
    )
    return rec, model


def _on_file(model: Model) -> Model:
    """``model`` read from a file, as the firmware is built from one: the model embedded in a run file or
    log is written to a private temporary file; a model narrowed to fewer axes is refused."""
    from accelnav.model.load import load_model, loads_model

    if Path(str(model.source)).is_file():
        return model
    whole = loads_model(model.text, source=str(model.source))
    if [a.name for a in whole.axes] != [a.name for a in model.axes]:
        names = ", ".join(a.name for a in model.axes)
        raise UserError(
            f"{model.source}: the firmware is built from a model file; give --model with the axes {names} only"
        )
    import tempfile

    path = Path(tempfile.mkdtemp(prefix="accelnav-hil-")) / f"{model.name}.toml"
    path.write_text(model.text)
    return load_model(path)


def stimulus(man: Manifest, run: SimRun | RecordedRun) -> bytes:
    """The stimulus frames of a simulated run: one per sample, the raw input of every axis; then a
    ``flush`` command, so that the compact mode sends its last, partial block and a checkpoint."""
    if run.code is not None:
        stim = encode_stimulus(man, code=run.code)
    else:
        stim = encode_stimulus(man, t1=run.t1, t2=run.t2)
    return stim + (encode_command(man, "flush") if "cmd_flush" in man.frames else b"")


def run_sil(model: Model, stim: bytes) -> bytes:
    """Feed ``stim`` to the host-board firmware in-process; returns its telemetry bytes."""
    fw = HostFirmware(build_firmware(model.source))
    fw.rx(stim)
    return fw.take()


@dataclass(frozen=True)
class PilResult:
    log: Path
    telemetry: bytes
    seconds: float
    stats: dict


def run_pil(
    model: Model,
    stim: bytes,
    n_samples: int,
    log: Path | Output,
    *,
    board: str = "mps2_an385",
    timeout_s: float = 600.0,
    link: str = "feed",
) -> PilResult:
    """Run the firmware on the emulated ``board`` with ``stim`` as its input and its telemetry in ``log``
    (written by the output rule, accelnav.fileio: a FIFO or a device is written through).

    ``link="feed"``: through files over semihosting (fast; the emulator exits at the end of
    ``stim``); ``link="uart"``: ``stim`` on the stimulus UART, the telemetry UART recorded by the
    recorder (the real link's path). Either way the run must yield ``n_samples`` sample frames."""
    if link == "uart":
        return _run_pil_uart(model, stim, n_samples, log, board=board, timeout_s=timeout_s)
    if link != "feed":
        raise ValueError(f"link {link!r}: accepted: feed, uart")
    # the emulator loads a private copy of the verified image, never the cache's file
    with private_firmware(board, model.source) as fw:
        elf = fw / "accelnav_fw.elf"
        if board in simavr.BOARDS:  # the AVR in simavr: its UART fed from a file by a libsimavr program
            source = f"simavr {simavr.MCU} (UART fed from a file)"
            t0 = time.monotonic()
            tel = simavr.run_feed(elf, stim, timeout=timeout_s).telemetry
        else:
            source = f"qemu {machine_for(board).machine} (file feed over semihosting)"
            t0 = time.monotonic()
            tel = run_feed(elf, board, stim, timeout=timeout_s)
        seconds = time.monotonic() - t0
    man = manifest(model.source)
    _write_log(log, man, model, source, tel)
    dec = Decoder(man, replay=replay_for(man, model))  # the compact frames' rows need the replay
    dec.feed(tel)
    dec.release()
    stats = dec.stats.as_dict()
    if stats.get("frames", {}).get("sample", 0) < n_samples:
        raise QemuError(f"PIL run ({board}) ended early (end of the stimulus) after {stats.get('frames', {})} frames")
    # the telemetry as received, every byte of which the log took: the log is not read back (a FIFO or a
    # device, which the output rule writes through, cannot be)
    return PilResult(Path(str(log)), tel, seconds, stats)


def _write_log(log: Path | Output, man: Manifest, model: Model, source: str, tel: bytes) -> None:
    """The telemetry of a PIL run as a recorder log (the output rule: a FIFO or a device is written through)."""
    from accelnav.link.logfile import LogWriter

    meta = {
        "manifest": man.data,
        "model_toml": model.text,
        "source": source,
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    try:
        with LogWriter(log, meta, overwrite=True, fsync_s=None) as writer:
            step = writer.max_chunk
            for a in range(0, len(tel), step):
                writer.append(tel[a : a + step])
                writer.flush()
    except OSError as exc:  # a full disk: the log holds what came before, said in one line
        raise UserError(f"{log}: cannot write the PIL log: {exc.strerror or exc}") from None


@dataclass(frozen=True)
class AdcPilResult:
    """An ADC board's run: its telemetry, SIL's on the codes it read, and the verdict."""

    telemetry: bytes
    sil: bytes
    codes: np.ndarray  # (n, n_axes): what the firmware read from its ADC, taken from its frames
    seconds: float  # the emulator's wall-clock time
    equal: bool  # the two telemetry streams are the same bytes
    first_difference: int | None  # byte offset of the first difference (or the shorter length)
    stats: dict  # the decoder's counts on the board's telemetry


def run_adc_pil(
    model: Model,
    n_samples: int,
    *,
    board: str = "netduino2",
    commands: tuple[str, ...] = (),
    timeout_s: float = 120.0,
    log: Path | Output | None = None,
) -> AdcPilResult:
    """Run ``model``'s firmware on an ADC board for ``n_samples`` sample periods (after ``commands``, names of
    argument-free commands such as ``mode_states``), then SIL on the codes it read, and compare.

    The codes come from the board's own frames (block frames in compact mode, sample frames otherwise), so
    SIL runs on exactly what the emulated ADC produced; in compact mode a last, unfinished block is not sent,
    and so not compared. A board that missed a sample (its main loop too slow)
    predicted over it without a code: SIL has no stimulus for that, so such a run is refused (QemuError),
    never called identical. ``log``: the board's telemetry also written there as a recorder log."""
    man = manifest(model.source)
    cmd = b"".join(encode_command(man, c) for c in commands)
    with private_firmware(board, model.source) as fw:
        t0 = time.monotonic()
        tel = run_adc(fw / "accelnav_fw.elf", board, n_samples, cmd, timeout=timeout_s)
        seconds = time.monotonic() - t0
    if log is not None:
        _write_log(log, man, model, f"qemu {board} (its TIM3 and ADC1 models; USART1 to a file)", tel)
    frames, st = decode_all(man, tel, replay_for(man, model))
    rows = frames["sample"]
    stats = st.as_dict()
    # the compact mode sends whole blocks: the samples of the last, unfinished one are not in the telemetry
    block = man.data["block_samples"] if "block" in man.frames and "mode_states" not in commands else 1
    if len(rows) != n_samples - n_samples % block:
        raise QemuError(f"{board}: {len(rows)} samples in the telemetry for {n_samples} sample periods")
    missed = int(rows["missed"][-1])
    if missed:
        raise QemuError(f"{board}: the board missed {missed} samples (no code read): SIL cannot replay them")
    codes = sample_columns(man, rows)["code"]
    sil = run_sil(model, cmd + encode_stimulus(man, code=codes))
    same = min(len(tel), len(sil))
    diff = np.flatnonzero(np.frombuffer(tel[:same], np.uint8) != np.frombuffer(sil[:same], np.uint8))
    first = int(diff[0]) if len(diff) else (None if len(tel) == len(sil) else same)
    return AdcPilResult(tel, sil, codes, seconds, first is None, first, stats)


def _run_pil_uart(
    model: Model, stim: bytes, n_samples: int, log: Path | Output, *, board: str, timeout_s: float
) -> PilResult:
    """run_pil over the board's UARTs, recorded by the recorder."""
    from accelnav.fileio import FILE, output_target
    from accelnav.link.logfile import read_log
    from accelnav.link.recorder import Recorder, Status

    out = output_target(log, stdout="the PIL log goes to a file")
    if out.kind != FILE:
        raise UserError(f"{out}: link uart reads the telemetry back from its log; give a file")
    m = machine_for(board)
    man = manifest(model.source)
    with private_firmware(board, model.source) as fw, QemuBoard(fw / "accelnav_fw.elf", board) as qb:
        tel = qb.open(m.telemetry)
        feed = qb.open(m.stimulus)  # the same port when one UART carries both
        wait_ready(tel, man, board)
        rec = Recorder(tel, out, man, model_text=model.text, commands=(), overwrite=True, status=Status(enabled=False))
        # the board reads its feed only while it has room to send: writing it all at once is safe
        writer = threading.Thread(target=feed.write, args=(stim,), daemon=True)
        writer.start()
        res = rec.run(max_frames=n_samples, duration=timeout_s)
        rec.log.close()  # the ports are the board's: it closes them
        writer.join(timeout=5)
    if res.reason != "frames":
        raise QemuError(f"PIL run ({board}) ended early ({res.reason}) after {res.stats.get('frames', {})} frames")
    return PilResult(out.path, b"".join(read_log(out.path).data), res.seconds, res.stats)


def wait_ready(tel, man: Manifest, board: str, timeout_s: float = 30.0) -> None:
    """Return once the firmware answers ``info`` on ``tel``, with the answers all read.

    Nothing may be fed before: QEMU's STM32 USART takes bytes from its socket
    even while the USART is still disabled, and drops them (its nRF51 and CMSDK
    UARTs wait), so a feed that starts before the firmware has set up its
    USARTs loses the first stimulus frame. ``info`` is resent every 0.2 s (a
    command that met a disabled USART is lost too) until an info frame comes
    back; then, with nothing more sent, the acks and any late answers are read
    until the line has been quiet for 0.3 s, so the recording starts on a
    frame boundary."""
    dec = Decoder(man)
    deadline = time.monotonic() + timeout_s
    infos = 0
    while infos == 0:
        if time.monotonic() > deadline:
            raise QemuError(f"{board}: no answer to 'info' within {timeout_s:g} s")
        tel.write(encode_command(man, "info"))
        t_end = time.monotonic() + 0.2
        while infos == 0 and time.monotonic() < t_end:
            infos += len(dec.feed(tel.read(4096))["info"])
    quiet_since = time.monotonic()
    while time.monotonic() - quiet_since < 0.3:
        if tel.read(4096):
            quiet_since = time.monotonic()


@dataclass
class Comparison:
    """What :func:`compare` found; ``rows`` feed the summary table."""

    n: int
    pil_equal_sil: bool | None  # None: no PIL run
    first_difference: int | None  # sample row (or, the rows equal, -1: a checkpoint or block frame differs)
    max_err_sigma: dict[str, float]  # firmware vs float64 reference, max |e|/sigma after the first second
    max_of_bound: float  # firmware vs the float64 Kalman filter, max |e| / the generator's stated bound (<= 1 required)
    position_rows: list[PositionErrors] = field(default_factory=list)
    link: dict = field(default_factory=dict)  # per target ("SIL", "PIL"): the decoder's counts (Stats.as_dict)
    fw: dict[str, np.ndarray] = field(default_factory=dict)
    ref_x: np.ndarray | None = None  # (n_axes, N, 4)
    ref_sd: np.ndarray | None = None
    smooth_x: np.ndarray | None = None
    zupt_x: np.ndarray | None = None


def stated_bound(model: Model, j: int, run: SimRun | RecordedRun, x_ref: np.ndarray) -> np.ndarray:
    """The generator's stated bound of |firmware - float64 Kalman filter| for axis column j of this
    run; ``x_ref`` is that filter (accelnav.estimate.kf.run_filter on the same input, same skips) for
    either form. See codegen.bounds.twin_bound."""
    from accelnav.codegen.bounds import twin_bound
    from accelnav.codegen.plan import schedule_for as _schedule_for
    from accelnav.codegen.ranges import plan_axis

    form = model.filter.form
    p = plan_axis(model, j, form)
    sched = _schedule_for(p) if form == "gain_schedule" else None
    valid = ~run.clipped[:, j]
    code = run.code[:, j] if run.code is not None else None
    bound, _ = twin_bound(p, code, run.accel[:, j], valid, x_ref, sched)
    return bound


def compare(model: Model, run: SimRun | RecordedRun, sil: bytes, pil: bytes | None = None) -> Comparison:
    """SIL vs PIL bit for bit, firmware vs float64 reference, truth vs firmware/reference/smoother (when the
    run has a truth: a RecordedRun has none, and no position-error rows)."""
    man = manifest(model.source)
    replay = replay_for(man, model)  # the compact mode's rows get their states from the firmware's own C
    sil_frames, sil_stats = decode_all(man, sil, replay)
    s = sil_frames["sample"]
    link = {"SIL": sil_stats.as_dict()}
    equal = first = None
    if pil is not None:
        pil_frames, pil_stats = decode_all(man, pil, replay)
        link["PIL"] = pil_stats.as_dict()
        p = pil_frames["sample"]
        same = min(len(p), len(s))
        # frame by frame, every byte of the decoded record (structured rows viewed as raw bytes)
        rows_p = p[:same].view(np.uint8).reshape(same, -1)
        rows_s = s[:same].view(np.uint8).reshape(same, -1)
        bad = np.flatnonzero((rows_p != rows_s).any(axis=1))
        equal = bool(len(p) == len(s) and len(bad) == 0)
        first = int(bad[0]) if len(bad) else (None if len(p) == len(s) else same)
        # the rows' states are the host's replay: what the boards computed is in the frames themselves
        for name in ("block", "checkpoint"):
            if name not in pil_frames:
                continue
            a, b = pil_frames[name], sil_frames[name]
            if len(a) != len(b) or a.tobytes() != b.tobytes():
                equal = False
                first = -1 if first is None else first
    cols = sample_columns(man, s)
    n = len(s)
    if n != len(run.t):
        raise ValueError(f"the firmware sent {n} sample frames for {len(run.t)} samples; it must send one each")
    n_axes = len(model.axes)
    ref_x = np.empty((n_axes, n, 4))
    ref_sd = np.empty((n_axes, n, 4))
    smooth_x = np.empty((n_axes, n, 4))
    errs = {k: 0.0 for k in STATES}
    of_bound = 0.0  # largest |firmware - float64| / stated bound, any state, any sample
    # the smoother with automatic zero-velocity updates, as `accelnav smooth --zupt auto` runs it
    arrays = run.to_arrays()
    rest = rest_mask(arrays["accel"], arrays["clipped"], model)
    zupt_x = smooth_run(arrays, model, rest=rest)["smooth_x"]
    start = int(round(model.rate_hz))  # after the first second, as the codegen lockstep tests
    for j in range(n_axes):
        d = axis_design(model, j)
        f = run_filter(d, run.accel[:, j], valid=~run.clipped[:, j], progress=False)
        sm = rts_smooth(d, f, progress=False)
        ref_x[j] = f.x_post
        ref_sd[j] = np.sqrt(np.einsum("kii->ki", f.P_post))
        smooth_x[j] = sm.x
        fw_x = np.column_stack([cols[key][:, j] for key in STATES])
        for i, key in enumerate(STATES):
            e = np.abs(fw_x[start:, i] - f.x_post[start:, i]) / ref_sd[j, start:, i]
            errs[key] = max(errs[key], float(e.max()) if len(e) else 0.0)
        bound = stated_bound(model, j, run, f.x_post)
        of_bound = max(of_bound, float((np.abs(fw_x - f.x_post) / bound).max()))
    estimates = {
        "firmware filter": cols["r"].T,
        "float64 filter": ref_x[:, :, 0],
        "smoother": smooth_x[:, :, 0],
        "smoother + ZUPT": zupt_x[:, :, 0],
    }
    rows = [] if run.r is None else error_rows(run.axis_names, run.r, estimates)
    return Comparison(n, equal, first, errs, of_bound, rows, link, cols, ref_x, ref_sd, smooth_x, zupt_x)


def format_comparison(c: Comparison) -> str:
    lines = []
    if c.pil_equal_sil is not None:
        where = "in a block or checkpoint frame" if c.first_difference == -1 else f"from row {c.first_difference}"
        verdict = "bit-identical" if c.pil_equal_sil else f"DIFFERENT {where}"
        lines.append(f"PIL vs SIL: {c.n} sample rows, {verdict}")
    for target, st in c.link.items():
        if st["frames"].get("block", 0):
            mism = f"{st['mismatches']} MISMATCHED" if st["mismatches"] else "no mismatch"
            lines.append(
                f"{target}: {st['frames']['block']} block frames, replay matched {st['checkpoints']} checkpoints "
                f"bit for bit, {mism}"
            )
    errs = ", ".join(f"{k} {v:.2e}" for k, v in c.max_err_sigma.items())
    lines.append(f"firmware vs float64 reference, max |error| / reference sigma after 1 s: {errs}")
    verdict = "within" if c.max_of_bound <= 1.0 else "OUTSIDE"
    lines.append(
        f"firmware vs float64 reference: {verdict} the generator's stated bound (at most {c.max_of_bound:.2f} of it)"
    )
    if c.position_rows:  # none for a recording: no truth to measure them against
        lines.append("")
        lines.append(format_errors(c.position_rows))
    return "\n".join(lines)
