"""The recorder on a full disk (issue 21, item 8): the recording ends with one line and its summary, and
the log written so far stays readable. The disk is a monkeypatched write that fails after N bytes."""

from __future__ import annotations

import errno
import os
import threading

import numpy as np
import pytest
import serial

import accelnav.link.logfile as logfile
from accelnav.cli import main
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.recorder import Recorder, Status, decode_log
from accelnav.model.load import load_model


class _FullDisk:
    """``os`` for the log writer, whose writes fill a disk of ``room`` bytes (short write, then ENOSPC)."""

    def __init__(self, room: int):
        self.room = room

    def __getattr__(self, name):
        return getattr(os, name)

    def write(self, fd, data):
        if self.room <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        n = os.write(fd, bytes(data[: self.room]))
        self.room -= n
        return n


@pytest.fixture(scope="module")
def telemetry(man):
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_command(man, "mode_states"))
    fw.take()
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(8).integers(-60, 60, (2000, 2))))
    return fw.take()


def test_a_full_disk_ends_the_recording_and_the_log_stays_readable(tmp_path, man, telemetry, monkeypatch):
    out = tmp_path / "full.acnlog"
    port = serial.serial_for_url("loop://", timeout=0.02)
    writer = threading.Thread(target=port.write, args=(telemetry,), daemon=True)
    room = len(telemetry) // 2  # the header and some chunks of up to 64 KiB fit
    monkeypatch.setattr(logfile, "os", _FullDisk(room))
    rec = Recorder(port, out, man, commands=(), model_text=load_model().text, status=Status(enabled=False))
    writer.start()
    res = rec.run(max_frames=2000, duration=30)
    rec.close()
    writer.join(5)
    assert res.reason == "log write failed: No space left on device"
    assert out.stat().st_size == room  # the short write kept what fitted: a torn last chunk
    d = decode_log(out)
    assert 0 < len(d.frames["sample"]) < 2000 and d.torn_bytes > 0  # a prefix of the stream, readable
    np.testing.assert_array_equal(d.frames["sample"]["index"], np.arange(len(d.frames["sample"])))
    # the summary counts what the log holds (it said 8 192 samples where the log held 8 128)
    assert res.stats == d.stats


def test_record_on_a_full_disk_says_so_in_one_line_with_its_summary(tmp_path, capsys, monkeypatch):
    out = tmp_path / "full.acnlog"
    monkeypatch.setattr(logfile, "os", _FullDisk(room=0))
    full = logfile.os
    full.room = 1 << 20  # the header goes in; loop:// echoes the info command back: that chunk does not
    real_init = logfile.LogWriter.__init__

    def init_then_fill(self, *a, **k):
        real_init(self, *a, **k)
        full.room = 0

    monkeypatch.setattr(logfile.LogWriter, "__init__", init_then_fill)
    status = main(["record", "loop://", "--out", str(out), "--duration", "1"])
    cap = capsys.readouterr()
    assert status == 1
    assert cap.err.count("\n") == 1 and "error: " in cap.err and "No space left on device" in cap.err, cap.err
    assert " samples, lost " in cap.out and "(log write failed: No space left on device)" in cap.out  # format_counts
    assert decode_log(out).chunks == 0  # the header alone: a readable, empty log
