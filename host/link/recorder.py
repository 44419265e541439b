"""Record a telemetry link to a log: pyserial in, :mod:`accelnav.link.logfile` out, decoded live for the status line.

Every link goes through ``serial.serial_for_url``: a real port (``/dev/ttyUSB0``,
``COM3``), a pty (``/dev/pts/7``), a TCP socket such as QEMU's ``-serial``
(``socket://localhost:5760``) or ``loop://`` for tests. The recorder writes
the raw bytes to the log (nothing is lost to a decoding problem), decodes them
as they come with :class:`accelnav.link.telemetry.Decoder` for the status line (rate,
frames, lost frames, CRC errors), checks the info frame against its manifest,
and stops on SIGINT/SIGTERM, after ``duration`` or ``max_frames``, or when the
link goes away (the log is closed cleanly in every case).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import serial

from accelnav.link.logfile import LogWriter
from accelnav.link.telemetry import Decoder, Manifest, encode_command

DEFAULT_BAUD = 921600


@dataclass
class Result:
    reason: str  # "duration", "frames", "stopped", "link lost: ..."
    seconds: float
    stats: dict
    info_ok: bool | None  # None: no info frame seen
    warnings: list[str] = field(default_factory=list)


class Status:
    """The live status line (stderr, redrawn at most 4 times a second)."""

    def __init__(self, stream=None, enabled: bool | None = None):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = bool(getattr(self.stream, "isatty", lambda: False)()) if enabled is None else enabled
        self._last = 0.0
        self._prev = (0.0, 0)
        self.rate = 0.0

    def line(self, t: float, dec: Decoder) -> str:
        s = dec.stats
        n = s.frames.get("sample", 0)
        t0, n0 = self._prev
        if t - t0 >= 1.0:
            self.rate = (n - n0) / (t - t0)
            self._prev = (t, n)
        return (
            f"{t:7.1f} s  {self.rate:7.1f} frames/s  {n:9d} frames  lost {s.lost}  dup {s.duplicates}  "
            f"CRC errors {s.crc_errors}  bad {s.bad_frames}  {s.bytes / 1024:8.1f} KiB"
        )

    def update(self, t: float, dec: Decoder, final: bool = False) -> None:
        if not self.enabled:
            return
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
    ):
        self.man = manifest
        if isinstance(port, str):
            self.url = port
            self.ser = serial.serial_for_url(port, baudrate=baud, timeout=0.02, do_not_open=False)
        else:
            self.url = getattr(port, "portstr", None) or getattr(port, "name", "?")
            self.ser = port
            self.ser.timeout = 0.02
        self.commands = commands
        self.decoder = Decoder(manifest)
        self.status = status or Status()
        meta = {
            "manifest": manifest.data,
            "model_toml": model_text,
            "source": str(self.url),
            "baud": baud,
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
        self.log = LogWriter(out, meta, flush_s=flush_s, overwrite=overwrite)
        self.info_ok: bool | None = None
        self.warnings: list[str] = []
        self._stop = False

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

    def run(self, duration: float | None = None, max_frames: int | None = None) -> Result:
        t0 = time.monotonic()
        reason = "stopped"
        try:
            for name, args in self.commands:
                self.ser.write(encode_command(self.man, name, **args))
            while not self._stop:
                try:
                    n = self.ser.in_waiting
                    data = self.ser.read(max(1, min(n, 1 << 16)))
                except (serial.SerialException, OSError) as exc:
                    reason = f"link lost: {exc}"
                    break
                now_ns = time.time_ns()
                self.log.append(data, now_ns)
                if data:
                    batch = self.decoder.feed(data)
                    if len(batch["info"]):
                        self._check_info(batch["info"])
                t = time.monotonic() - t0
                self.status.update(t, self.decoder)
                if duration is not None and t >= duration:
                    reason = "duration"
                    break
                if max_frames is not None and self.decoder.stats.frames.get("sample", 0) >= max_frames:
                    reason = "frames"
                    break
        finally:
            self.log.close()
            self.status.update(time.monotonic() - t0, self.decoder, final=True)
        return Result(reason, time.monotonic() - t0, self.decoder.stats.as_dict(), self.info_ok, self.warnings)

    def close(self) -> None:
        self.log.close()
        try:
            self.ser.close()
        except (serial.SerialException, OSError):
            pass


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


def decode_log(path) -> DecodedLog:
    """Read a log and decode its bytes with the manifest stored in it."""
    import numpy as np

    from accelnav.link.logfile import read_log

    contents = read_log(path)
    man = Manifest(contents.meta["manifest"])
    dec = Decoder(man)
    parts: dict[str, list] = {n: [] for n in dec.names}
    times = []
    for t_ns, data in zip(contents.times, contents.data, strict=True):
        batch = dec.feed(data)
        for n in parts:
            parts[n].append(batch[n])
        times.append(np.full(len(batch["sample"]), t_ns, np.int64))
    dec.finish()
    frames = {n: (np.concatenate(p) if p else np.zeros(0, man.dtypes[n])) for n, p in parts.items()}
    host_t = np.concatenate(times) if times else np.zeros(0, np.int64)
    return DecodedLog(
        man,
        contents.meta,
        frames,
        host_t,
        dec.stats.as_dict(),
        len(contents.data),
        contents.damaged_bytes,
        contents.torn_bytes,
    )
