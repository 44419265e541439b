"""Record a telemetry link to a log: pyserial in, :mod:`accelnav.link.logfile` out, decoded live for the status line.

Every link goes through ``serial.serial_for_url``: a real port (``/dev/ttyUSB0``,
``COM3``), a pty (``/dev/pts/7``), a TCP socket such as QEMU's ``-serial``
(``socket://localhost:5760``) or ``loop://`` for tests. The recorder writes
the raw bytes to the log (nothing is lost to a decoding problem), decodes them
as they come with :class:`accelnav.link.decoder.Decoder` for the status line (rate,
frames, lost frames, CRC errors), checks the info frame against its manifest,
and stops on SIGINT/SIGTERM or after ``duration`` or ``max_frames`` (the log
is closed cleanly in every case).

A pulled cable (the port raises, a socket closes) does not end a recording
opened from a URL: the log stays open, the port is reopened with backoff
(0.1 s doubling to 2 s) while the status line says so, the commands are sent
again on reconnection, and the gap is recorded (``Result.gaps``: how long, and
how many frames the sample index says were lost) before recording carries on.
``give_up_after`` (seconds without the link) ends it with ``link lost``.
"""

from __future__ import annotations

import copy
import select
import sys
import time
from dataclasses import dataclass, field

import serial
from serial.urlhandler.protocol_socket import Serial as SocketSerial

from accelnav.link.codec import encode_command
from accelnav.link.decoder import Decoder, end_of_stream, replay_for
from accelnav.link.logfile import LogWriter
from accelnav.link.manifest import Manifest
from accelnav.native.cbuild import BuildError

DEFAULT_BAUD = 921600


@dataclass
class Result:
    reason: str  # "duration", "frames", "stopped", "link lost: ..."
    seconds: float
    stats: dict
    info_ok: bool | None  # None: no info frame seen
    warnings: list[str] = field(default_factory=list)
    gaps: list[dict] = field(default_factory=list)  # per outage of the link: see Recorder.run


BACKOFF_S = (0.1, 2.0)  # first retry delay, longest delay


class Status:
    """The live status line (stderr, redrawn at most 4 times a second).

    It counts the samples received (:attr:`Decoder.received`), not the rows delivered: in the compact mode
    rows go out only when a checkpoint closes their stretch, so a count of delivered rows reads 0 for the
    first checkpoint interval and then jumps. The rate is taken between arrivals (the moments the count
    grew) over the last ``RATE_WINDOW_S``: bytes come a block at a time, so a rate between fixed redraw
    moments swings by a block per window."""

    RATE_WINDOW_S = 2.0

    def __init__(self, stream=None, enabled: bool | None = None):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)()) if enabled is None else enabled
        self._last = 0.0
        self._arrivals: list[tuple[float, int]] = []  # (time, samples received) when the count grew
        self.note = ""  # shown instead of the counters while set (link lost, retrying)

    def event(self, t: float, text: str) -> None:
        """A one-line event (link lost, link back), written even when the live line is off."""
        self.stream.write(("\r" if self.enabled else "") + f"{t:7.1f} s  {text}\n")
        self.stream.flush()

    def seen(self, t: float, dec: Decoder) -> None:
        """Note the samples received by time ``t`` (after every read)."""
        n = dec.received
        if not self._arrivals or n > self._arrivals[-1][1]:
            self._arrivals.append((t, n))
        while len(self._arrivals) > 2 and self._arrivals[1][0] < t - self.RATE_WINDOW_S:
            self._arrivals.pop(0)

    def rate(self, t: float) -> float:
        """Samples per second between the first and last arrival in the window (0 once nothing came for a
        window, or before two arrivals)."""
        a = [x for x in self._arrivals if x[0] >= t - self.RATE_WINDOW_S]
        if len(a) < 2 or a[-1][0] <= a[0][0]:
            return 0.0
        return (a[-1][1] - a[0][1]) / (a[-1][0] - a[0][0])

    def line(self, t: float, dec: Decoder) -> str:
        if self.note:
            return f"{t:7.1f} s  {self.note}"
        s = dec.stats
        line = (
            f"{t:7.1f} s  {self.rate(t):7.1f} frames/s  {dec.received:9d} frames  lost {s.lost}  "
            f"dup {s.duplicates}  CRC errors {s.crc_errors}  bad {s.bad_frames}  {s.bytes / 1024:8.1f} KiB"
        )
        if s.frames.get("block"):  # compact mode: the replay's checks
            line += f"  checkpoints {s.checkpoints}" + (f"  MISMATCHES {s.mismatches}" if s.mismatches else "")
            if s.unreplayed:
                line += "  (not replayed: no model text)"
        return line

    def update(self, t: float, dec: Decoder, final: bool = False) -> None:
        if not self.enabled:
            return
        self.seen(t, dec)
        if final or t - self._last >= 0.25:
            self._last = t
            self.stream.write("\r" + self.line(t, dec) + ("\n" if final else ""))
            self.stream.flush()


class Recorder:
    """Record ``port`` (a URL or an open pyserial object) into a new log at ``out``."""

    def __init__(
        self,
        port,
        out,
        manifest: Manifest,
        *,
        baud: int = DEFAULT_BAUD,
        model_text: str = "",
        commands: tuple[tuple[str, dict], ...] = (("info", {}),),
        overwrite: bool = False,
        flush_s: float = 0.1,
        status: Status | None = None,
        on_rows=None,
    ):
        self.man = manifest
        self.on_rows = on_rows  # called with each batch of decoded sample rows (a live plot): must be quick
        self.baud = baud
        self.reopen = isinstance(port, str)  # a URL can be opened again after the link is lost
        if isinstance(port, str):
            self.url = port
            self.ser = self._open()
        else:
            self.url = getattr(port, "portstr", None) or getattr(port, "name", "?")
            self.ser = port
            self.ser.timeout = 0.02
        self.commands = commands
        self.warnings: list[str] = []
        self.decoder = Decoder(manifest, replay=_replay(manifest, model_text, self.warnings))
        self.status = status or Status()
        meta = {
            "manifest": manifest.data,
            "model_toml": model_text,
            "source": str(self.url),
            "baud": baud,
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
        self.log = LogWriter(out, meta, flush_s=flush_s, overwrite=overwrite)
        self.model_text = model_text
        self.info_ok: bool | None = None
        self._stop = False

    def _open(self):
        ser = serial.serial_for_url(self.url, baudrate=self.baud, timeout=0.02, do_not_open=True)
        if isinstance(ser, SocketSerial):
            # pyserial's socket open() ends by discarding what already arrived: a device that starts
            # sending on connection (QEMU's serial socket) lost its first frames to it
            ser.reset_input_buffer = lambda: None
            try:
                ser.open()
            finally:
                del ser.reset_input_buffer
        else:
            ser.open()
        return ser

    def stop(self) -> None:
        """Ask run() to finish (from a signal handler or another thread)."""
        self._stop = True

    def _check_info(self, info) -> None:
        for rec in info:
            ok = int(rec["layout_hash"]) == self.man.layout_hash
            sha = bytes(rec["model_sha256"]).hex()
            if not ok:
                self.warnings.append(
                    f"the device's frame layout 0x{int(rec['layout_hash']):08x} differs from the manifest's "
                    f"0x{self.man.layout_hash:08x}: the log keeps the raw bytes, but decode it with the right manifest"
                )
            elif sha != self.man.model_sha256:
                self.warnings.append(
                    f"the device runs model {sha[:12]}, the manifest is for {self.man.model_sha256[:12]}"
                )
            self.info_ok = ok if self.info_ok is None else (self.info_ok and ok)

    def run(
        self, duration: float | None = None, max_frames: int | None = None, give_up_after: float | None = None
    ) -> Result:
        """Record until stopped, ``duration`` s, ``max_frames`` sample frames, or ``give_up_after`` s without
        the link (``None``: retry until stopped). Each entry of ``Result.gaps``: ``lost_s`` and ``back_s``
        (recording time the link went and came back), ``attempts``, ``index_before`` (last sample index before
        it), and once a sample frame arrived after it ``index_after`` and ``frames_lost`` (counted exactly
        from the sample index by the decoder)."""
        t0 = time.monotonic()
        reason = "stopped"
        gaps: list[dict] = []
        pending: dict | None = None  # the last gap, until a sample frame tells how long it was
        try:
            self._send_commands()
            while not self._stop:
                if self.ser is None:
                    reason = self._reconnect(t0, gaps[-1], duration, give_up_after)
                    if reason:
                        break
                    pending = gaps[-1]
                    continue
                try:
                    data = self._read()
                except (serial.SerialException, OSError) as exc:
                    if not self.reopen or give_up_after == 0:
                        reason = f"link lost: {exc}"
                        break
                    gaps.append(self._lost(time.monotonic() - t0, exc))
                    pending = None
                    continue
                now_ns = time.time_ns()
                self.log.append(data, now_ns)
                if data:
                    before = copy.deepcopy(self.decoder.order) if pending is not None else None
                    lost0 = self.decoder.stats.lost
                    batch = self.decoder.feed(data)
                    if len(batch["info"]):
                        self._check_info(batch["info"])
                    rows = batch["sample"]
                    if self.on_rows is not None and len(rows):
                        self.on_rows(rows)
                    if pending is not None and self.decoder.compact is not None and pending["index_before"] is not None:
                        rows = rows[rows["index"] > pending["index_before"]]  # not rows held from before the gap
                    if pending is not None and len(rows):
                        lost = self.decoder.stats.lost - lost0
                        self._gap_measured(pending, before, rows[0], time.monotonic() - t0, lost)
                        pending = None
                t = time.monotonic() - t0
                self.status.update(t, self.decoder)
                if duration is not None and t >= duration:
                    reason = "duration"
                    break
                if max_frames is not None and self.decoder.stats.frames.get("sample", 0) >= max_frames:
                    reason = "frames"
                    break
            if reason in ("duration", "frames", "stopped") and self.ser is not None:
                self._end_of_frame()  # a clean stop ends on a frame boundary, not on a torn frame counted damaged
        except OSError as exc:
            if self.log.error is None:  # not the log's write: not ours to explain
                raise
            reason = f"log write failed: {exc.strerror or exc}"  # a full disk: end here, the log stays readable
        finally:
            self.log.close()
            rest = end_of_stream(self.decoder)  # as every reader of the log ends it: the same counts
            if self.on_rows is not None and len(rest):
                self.on_rows(rest)
            self.status.note = ""
            self.status.update(time.monotonic() - t0, self.decoder, final=True)
        stats = self.decoder.stats.as_dict()
        if self.log.error is not None:  # bytes decoded here never reached the log: count what it holds
            stats = self._logged_stats(stats)
        hint = garbage_hint(stats, self.man, self.baud)
        if hint:
            self.warnings.append(f"{self.url}: {hint}")
        return Result(reason, time.monotonic() - t0, stats, self.info_ok, self.warnings, gaps)

    def _logged_stats(self, decoded: dict) -> dict:
        """The counts of the log as written (a write failed: the last chunk is torn or missing), as
        ``log info`` will show them; the decoder's own counts if the log cannot be read back."""
        from accelnav.link.logfile import LogError

        try:
            return decode_log(self.log.path, self.model_text, rows=False).stats
        except (LogError, OSError) as exc:
            self.warnings.append(f"{self.log.path}: cannot read the log back to count it ({exc}): counts as received")
            return decoded

    def _end_of_frame(self, wait_s: float = 0.5) -> None:
        """Stopping (a frame count, the duration, Ctrl-C) with a frame under way (the next one began in the
        same read): read on, at most ``wait_s``, up to its delimiter, so that the log ends on a frame boundary
        rather than in a torn frame that would read as damage."""
        end = time.monotonic() + wait_s
        while self.decoder.mid_frame and time.monotonic() < end:
            try:
                data = self._read()
            except (serial.SerialException, OSError):
                return  # the link went: the log ends as it is
            k = data.find(b"\0")
            data = data if k < 0 else data[: k + 1]
            if data:
                self.log.append(data, time.time_ns())
                rows = self.decoder.feed(data)["sample"]
                if self.on_rows is not None and len(rows):
                    self.on_rows(rows)

    def _read(self) -> bytes:
        """What the link has (at most 64 KiB), waiting up to the port's timeout for the first byte."""
        if isinstance(self.ser, SocketSerial):
            # pyserial's socket in_waiting is 0 or 1 (readable or not): one byte per read made the recorder
            # the bottleneck of PIL; take everything the socket holds, and see the peer's close as pyserial does
            sock = self.ser._socket
            if not select.select([sock], [], [], self.ser.timeout)[0]:
                return b""
            data = sock.recv(1 << 16)
            if not data:
                raise serial.SerialException("socket disconnected")
            return data
        n = self.ser.in_waiting
        return self.ser.read(max(1, min(n, 1 << 16)))

    def _send_commands(self) -> None:
        for name, args in self.commands:
            self.ser.write(encode_command(self.man, name, **args))

    def _lost(self, t: float, exc: Exception) -> dict:
        """The link went away: close the port, keep the log. The unfinished frame stays with the decoder: the
        bytes after the link comes back join it, as they join in the log, so the recorder counts damage as
        every reader of the log does (it was refused here as well, one damaged frame more per outage)."""
        try:
            self.ser.close()
        except (serial.SerialException, OSError):
            pass
        self.ser = None
        self.log.flush()
        gap = {"lost_s": round(t, 3), "error": str(exc), "index_before": self.decoder.last_index, "attempts": 0}
        self.status.event(t, f"link lost ({exc}); the log stays open, retrying {self.url}")
        return gap

    def _reconnect(self, t0: float, gap: dict, duration: float | None, give_up_after: float | None) -> str:
        """Reopen the port with backoff; '' once open, else why the recording ends."""
        delay = BACKOFF_S[0]
        while not self._stop:
            t_retry = time.monotonic() + delay
            while time.monotonic() < t_retry:  # wait in small steps: Ctrl-C, duration and the log's flush
                t = time.monotonic() - t0
                if self._stop:
                    return "stopped"
                if duration is not None and t >= duration:
                    return "duration"
                if give_up_after is not None and t - gap["lost_s"] >= give_up_after:
                    return f"link lost: {gap['error']} (no link for {t - gap['lost_s']:.1f} s)"
                self.log.poll()
                self.status.note = (
                    f"link lost {t - gap['lost_s']:.1f} s ago: retrying {self.url} "
                    f"(attempt {gap['attempts'] + 1} in {max(0.0, t_retry - time.monotonic()):.1f} s)"
                )
                self.status.update(t, self.decoder)
                time.sleep(min(0.05, max(0.0, t_retry - time.monotonic())))
            gap["attempts"] += 1
            try:
                self.ser = self._open()
                self._send_commands()
            except (serial.SerialException, OSError, ValueError):
                if self.ser is not None:
                    try:
                        self.ser.close()
                    except (serial.SerialException, OSError):
                        pass
                self.ser = None
                delay = min(2 * delay, BACKOFF_S[1])
                continue
            t = time.monotonic() - t0
            gap["back_s"] = round(t, 3)
            self.status.note = ""
            self.status.event(t, f"link back after {t - gap['lost_s']:.1f} s ({gap['attempts']} attempts)")
            return ""
        return "stopped"

    def _gap_measured(self, gap: dict, before, first, t: float, batch_lost: int) -> None:
        """The first sample row after a reconnection: the rows the gap cost, exactly (the decoder's rule).
        A sample frame is stepped through the state mode's rule; a replayed row (compact mode) takes the
        samples the decoder counted lost in the batch that brought it (the gap and the stretch to the first
        checkpoint after it)."""
        if int(first["flags"]) & (1 << self.man.flags.get("replayed", 99)):
            gap["index_after"] = int(first["index"])
            gap["frames_lost"] = batch_lost
        else:
            lost0 = before.lost
            before.step(int(first["seq"]), int(first["index"]), int(first["flags"]))
            gap["index_after"] = int(first["index"])
            gap["frames_lost"] = before.lost - lost0
        self.status.event(
            t,
            f"gap recorded: sample index {gap['index_before']} -> {gap['index_after']}, "
            f"{gap['frames_lost']} frames lost while the link was away",
        )

    def close(self) -> None:
        self.log.close()
        if self.ser is None:
            return
        try:
            self.ser.close()
        except (serial.SerialException, OSError):
            pass


def _replay(man: Manifest, model_text: str, warnings: list, source: str = "the recording"):
    """The replay for the compact mode's frames, or None (with a warning when the frames need one)."""
    if "block" not in man.frames:
        return None
    if not model_text:
        warnings.append(f"{source}: no model text: the compact frames' samples cannot be replayed (unreplayed)")
        return None
    try:
        return replay_for(man, model_text)
    except (ValueError, BuildError, ImportError, OSError) as exc:  # ReplayError, ModelError, no compiler, a
        # cached build that does not load: one line, read by whoever asks why the samples have no rows
        warnings.append(f"{source}: {str(exc).splitlines()[0]}")
        return None


@dataclass
class DecodedLog:
    manifest: Manifest
    meta: dict
    frames: dict  # frame name -> structured array, stream order
    host_t_ns: object  # (n_samples,) int64: host time of the chunk each sample frame arrived in
    stats: dict
    chunks: int
    damaged_bytes: int
    torn_bytes: int
    warnings: list = field(default_factory=list)


def decode_log(path, model_text: str = "", *, rows: bool = True) -> DecodedLog:
    """Read a log and decode its bytes with the manifest stored in it; the compact mode's samples are
    replayed with the model text stored in it, else with ``model_text`` (a log recorded with --manifest).

    The log is streamed; ``rows=False`` keeps only the first and last row of each frame kind (what a
    summary needs), so memory does not grow with the log."""
    import numpy as np

    from accelnav.link.compact import concat_records
    from accelnav.link.logfile import LogError, LogReader
    from accelnav.model.load import loads_model

    with LogReader(path) as log:
        if not isinstance(log.meta.get("manifest"), dict):
            raise LogError(f"{path}: the header has no frame manifest (an object under 'manifest')")
        own = log.meta.get("model_toml")
        if own is not None and not isinstance(own, str):
            raise LogError(f"{path}: the header's model_toml is not text")
        try:
            man = Manifest(log.meta["manifest"])
        except (KeyError, TypeError, ValueError, AttributeError, IndexError) as exc:
            raise LogError(f"{path}: the header's frame manifest is not valid ({str(exc)[:60]})") from None
        warnings: list[str] = []
        text = own or model_text
        if text:  # the log's model is someone else's file: the loader's rule first, or nothing is read (ModelError)
            model = loads_model(text, source=f"{path}:model_toml" if own else "--model")
            same_input(model, man, str(path), "its model_toml" if own else "the model given")
        dec = Decoder(man, replay=_replay(man, text, warnings, str(path)))
        parts: dict[str, list] = {n: [] for n in dec.names}
        times: list = []
        t_last = 0
        for t_ns, data in log:
            batch = dec.feed(data)
            for n in parts:
                _keep(parts[n], batch[n], rows)
            _keep(times, np.full(len(batch["sample"]), t_ns, np.int64), rows)
            t_last = t_ns
    rest = end_of_stream(dec)  # rows after the last checkpoint: the recording ended before the next one
    if len(rest):
        _keep(parts["sample"], rest, rows)
        _keep(times, np.full(len(rest), t_last, np.int64), rows)
    frames = {n: concat_records(p, man.dtypes[n]) for n, p in parts.items()}
    host_t = np.concatenate(times) if times else np.zeros(0, np.int64)
    return DecodedLog(
        man,
        log.meta,
        frames,
        host_t,
        dec.stats.as_dict(),
        log.chunks,
        log.damaged_bytes,
        log.torn_bytes,
        warnings,
    )


def garbage_hint(stats: dict, man: Manifest, baud: int) -> str | None:
    """Why a link that sent bytes gave no frame at all, from what came (None when a frame came, or nothing):
    no delimiter in the bytes is what a wrong baud rate gives; delimited segments none of which is a frame
    of this manifest are a firmware of another layout (or a baud rate that keeps the zero bytes)."""
    if stats["bytes"] == 0 or any(stats["frames"].values()):
        return None
    n, segs = stats["bytes"], stats["bad_frames"]
    sizes = sorted({int(f["size"]) + 5 for f in man.frames.values() if f["direction"] == "up"})
    if segs <= 1:
        return (
            f"{n} bytes and no frame delimiter (zero byte) in them: a wrong baud rate garbles every byte "
            f"(now {baud}: give the firmware's with --baud)"
        )
    return (
        f"{n} bytes in {segs} delimited segments (mean {n / segs:.0f} bytes; this manifest's frames are "
        f"{sizes[0]} to {sizes[-1]}), none a frame of this manifest: a firmware of another model or layout "
        f"(give its --manifest or --model), or a wrong baud rate (now {baud}: --baud)"
    )


def same_input(model, man: Manifest, log: str, who: str) -> None:
    """Refuse in one line a model whose part is read otherwise than the log's frames carry (a duty-cycle model
    for ADC codes, or the reverse): its conversion cannot take them."""
    duty = model.sensor.kind == "duty_cycle"
    if duty != (man.input == "duty_cycle"):
        from accelnav.link.logfile import LogError

        frames = "(T1, T2) duty-cycle pairs" if man.input == "duty_cycle" else "ADC codes"
        raise LogError(
            f"{log}: {who} is a {model.sensor.kind.replace('_', '-')} part but the log's frames carry {frames}: "
            "not the model the firmware was built with"
        )


def _keep(parts: list, rows, every: bool) -> None:
    """Collect ``rows``: all of them, or only the first row seen and the last."""
    if every:
        parts.append(rows)
    elif len(rows):
        if not parts:
            parts.append(rows[:1])
        parts[1:] = [rows[-1:]]
