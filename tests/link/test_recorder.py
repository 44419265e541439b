"""The log format and the recorder: loop://, a pty, kill -9 mid-stream, a pulled cable, log info/export."""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import serial
from conftest import REPO
from support.frames import split_frames
from support.link_server import server
from support.loop_record import record_loop

from accelnav.cli import main as cli_main
from accelnav.data.logs import log_summary
from accelnav.data.runfile import load_run
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, generated
from accelnav.link.accounting import format_counts, link_counts
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.decoder import decode_all
from accelnav.link.logfile import LogError, LogWriter, read_log
from accelnav.link.recorder import Recorder, Status, decode_log
from accelnav.model.load import load_model


@pytest.fixture(scope="module")
def telemetry(man):
    """2000 samples of the default model's firmware (host board, cffi) in the state mode (one sample frame
    per sample, its states included): its telemetry bytes."""
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_command(man, "mode_states"))
    fw.take()  # the ack
    code = 2048 + np.random.default_rng(8).integers(-60, 60, (2000, 2))
    fw.rx(encode_stimulus(man, code=code))
    return fw.take()


@pytest.fixture
def manifest_file(tmp_path):
    p = tmp_path / "acnframe.json"
    p.write_text(generated(None)["acnframe.json"])
    return p


# --------------------------------------------------------------------------
# log file


def test_log_round_trip_and_chunking(tmp_path):
    clock = iter(range(0, 10**12, 30_000_000))  # 30 ms per call
    path = tmp_path / "a.acnlog"
    pieces = [bytes([k % 251 + 1]) * (k + 1) for k in range(40)]
    with LogWriter(path, {"x": 1}, clock=lambda: next(clock), fsync_s=None) as log:
        for p in pieces:
            log.append(p)
    got = read_log(path)
    assert got.meta["x"] == 1 and got.meta["format"] == "accelnav-log/1"
    assert b"".join(got.data) == b"".join(pieces)
    assert 8 <= len(got.data) <= 14  # one chunk per 0.1 s of 30 ms appends
    assert got.torn_bytes == 0 and got.damaged_bytes == 0


def test_log_survives_truncation_and_damage(tmp_path):
    path = tmp_path / "b.acnlog"
    t = iter(range(0, 10**12, 200_000_000))  # every append is its own chunk
    with LogWriter(path, {}, clock=lambda: next(t), fsync_s=None) as log:
        for k in range(20):
            log.append(bytes([k + 1]) * 100)
    whole = path.read_bytes()
    head_len = len(whole) - 20 * (20 + 100)
    for cut in range(head_len, len(whole), 7):  # torn anywhere: a prefix of the chunks, never an error
        path.write_bytes(whole[:cut])
        got = read_log(path)
        assert len(got.data) == (cut - head_len) // 120
        assert all(d == bytes([k + 1]) * 100 for k, d in enumerate(got.data))
    damaged = bytearray(whole)
    damaged[head_len + 5 * 120 + 50] ^= 0xFF  # inside chunk 5's bytes
    path.write_bytes(bytes(damaged))
    got = read_log(path)
    assert len(got.data) == 19 and got.damaged_bytes == 120
    path.write_bytes(b"not a log")
    with pytest.raises(LogError, match="not an accelnav log"):
        read_log(path)


def test_log_refuses_to_overwrite(tmp_path):
    path = tmp_path / "c.acnlog"
    LogWriter(path, {}).close()
    with pytest.raises(FileExistsError):
        LogWriter(path, {})


# --------------------------------------------------------------------------
# recorder in-process over loop://


def _loop_record(out, man, data: bytes, status: Status | None = None):
    """Record ``data`` sent through pyserial's loop:// (its queue holds 4 KiB: a thread writes)."""
    port = serial.serial_for_url("loop://", timeout=0.02)
    writer = threading.Thread(target=port.write, args=(data,), daemon=True)
    status = status or Status(enabled=False)
    rec = Recorder(port, out, man, commands=(), model_text=load_model().text, status=status)
    writer.start()
    res = rec.run(max_frames=2000, duration=30)
    rec.close()
    writer.join(5)
    return res


def test_recorder_over_loop(tmp_path, man, telemetry):
    junk = bytes(np.random.default_rng(1).integers(0, 256, 300, dtype=np.uint8))
    out = tmp_path / "loop.acnlog"
    cut = telemetry.index(b"\0", 50_000) + 1  # between two frames; the junk ends with a delimiter
    shown = io.StringIO()
    res = _loop_record(
        out, man, junk + b"\0" + telemetry[:cut] + junk + b"\0" + telemetry[cut:], Status(shown, enabled=True)
    )
    last = shown.getvalue().rstrip("\n").split("\r")[-1]
    assert re.search(r"frames/s +2000 frames +lost 0 +dup 0 +CRC errors 0 +bad \d+", last), last
    assert res.reason == "frames"
    assert res.stats["frames"]["sample"] == 2000
    d = decode_log(out)
    ref, _ = decode_all(man, telemetry)
    np.testing.assert_array_equal(d.frames["sample"], ref["sample"])
    assert d.stats["lost"] == 0 and d.stats["bad_frames"] >= 1  # the junk


def test_log_info_and_export(tmp_path, man, telemetry, capsys):
    out = tmp_path / "x.acnlog"
    _loop_record(out, man, telemetry)
    info = log_summary(out)  # what ``log info --json`` prints (its printing: tests/link/test_compact.py)
    assert info["frames"]["sample"] == 2000 and info["lost"] == 0 and info["axes"] == ["x", "y"]
    assert cli_main(["log", "export", str(out), "--out", str(tmp_path / "x.csv")]) == 0
    rows = np.loadtxt(tmp_path / "x.csv", delimiter=",", skiprows=1)
    assert rows.shape[0] == 2000
    assert cli_main(["log", "export", str(out), "--out", str(tmp_path / "x.npz")]) == 0
    arrays, model = load_run(tmp_path / "x.npz")
    assert arrays["fw_x"].shape == (2, 2000, 4) and model.name == "adxl250_default"
    ref = decode_all(man, telemetry)[0]["sample"]
    np.testing.assert_array_equal(arrays["code"][:, 0], ref["x.code"])
    # smooth takes the log directly, as if it were the exported run file
    for src, name in ((out, "from_log.npz"), (tmp_path / "x.npz", "from_run.npz")):
        assert cli_main(["smooth", str(src), "--zupt", "auto", "--out", str(tmp_path / name)]) == 0
    a, _ = load_run(tmp_path / "from_log.npz")
    b, _ = load_run(tmp_path / "from_run.npz")
    np.testing.assert_array_equal(a["smooth_x"], b["smooth_x"])
    # and fit-bias reads it too: the stimulus is uniform over +-60 codes, whose extreme codes hold more than
    # the rail detector's 0.5 %, so the fit refuses it, but only after reading the axis from the log
    capsys.readouterr()
    status = cli_main(["fit-bias", str(out), "--min-duration", "10", "--out", str(tmp_path / "fit.toml")])
    err = capsys.readouterr().err
    assert status == 2 and "x.acnlog: axis 'x': " in err and "sit at the m" in err and err.count("\n") == 1
    assert cli_main(["log", "info", str(tmp_path / "x.csv")]) == 2  # not a log: one line, status 2
    assert "not an accelnav log" in capsys.readouterr().err


def test_log_info_and_export_show_lost_duplicate_and_damaged_frames(tmp_path, man, telemetry, capsys):
    frames = split_frames(telemetry)
    damaged = bytearray(frames[1500])
    damaged[10] ^= 0x40  # refused and counted as damaged
    # frames 100..109 repeated, 1000..1003 lost, 1500 damaged (so lost too)
    stream = frames[:110] + frames[100:1000] + frames[1004:1500] + [bytes(damaged)] + frames[1501:]
    path = tmp_path / "faults.acnlog"
    with LogWriter(path, {"manifest": man.data, "model_toml": load_model().text}, fsync_s=None) as log:
        for k in range(0, len(stream), 64):
            log.append(b"".join(stream[k : k + 64]))
    info = log_summary(path)
    assert (info["lost"], info["duplicates"], info["damaged_frames"]) == (5, 10, 1)
    assert info["frames"]["sample"] == 2000 - 5
    assert cli_main(["log", "info", str(path)]) == 0
    text = capsys.readouterr().out
    assert re.search(r"^link +1995 samples, lost 5, duplicates 10, damaged 1 frames", text, re.M), text
    for suffix in ("csv", "npz"):
        assert cli_main(["log", "export", str(path), "--out", str(tmp_path / f"f.{suffix}")]) == 0
        assert "lost 5, duplicates 10, damaged 1 frames" in capsys.readouterr().out
    rows = np.loadtxt(tmp_path / "f.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rows[:, 1], np.r_[0:1000, 1004:1500, 1501:2000])  # each sample once


# --------------------------------------------------------------------------
# recorder as a program on a pty: kill -9, pulled cable


def _start_recorder(tmp_path, manifest_file, slave_name, out, *extra):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    cmd = [sys.executable, "-m", "accelnav.cli", "record", slave_name, "--out", str(out)]
    cmd += ["--manifest", str(manifest_file), "--no-commands", *extra]
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not out.exists():  # the header is written once the port is open
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the recorder did not start"
        time.sleep(0.02)
    return proc


def _feeder(master_fd, frames: list[bytes], rate_hz: float, sent: list, stop: threading.Event):
    """Write one frame every 1/rate_hz s; note (time, seq index) of each."""
    t0 = time.monotonic()
    for k, f in enumerate(frames):
        if stop.is_set():
            return
        delay = t0 + k / rate_hz - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        try:
            os.write(master_fd, f)
        except OSError:
            return
        sent.append((time.monotonic(), k))


@pytest.mark.parametrize("stop", ["frames", "duration"])
def test_a_stop_ends_the_log_on_a_frame_boundary(tmp_path, man, telemetry, stop):
    """The read that completes the count, or the duration's last read, also brings the start of the next frame
    (its rest comes a moment later): the recorder reads on to that frame's delimiter (at most 0.5 s), so the
    log holds no torn frame. A clean --duration stop was summed up as "damaged 1 frames"."""
    frames = split_frames(telemetry)
    head, extra = b"".join(frames[:20]), frames[20]
    out = tmp_path / f"{stop}.acnlog"
    run = {"max_frames": 20, "duration": 10} if stop == "frames" else {"duration": 0.3}
    later_s = 0.1 if stop == "frames" else 0.45
    text = load_model().text
    res = record_loop(man, out, head + extra[:30], later=extra[30:], later_s=later_s, model_text=text, **run)
    assert res.reason == stop
    assert res.stats["bad_frames"] == 0 and res.stats["frames"]["sample"] == 21
    assert "damaged 0 frames" in format_counts(link_counts(res.stats))
    d = decode_log(out)
    assert d.stats["bad_frames"] == 0 and d.stats["garbage_bytes"] == 0
    assert len(d.frames["sample"]) == 21


@pytest.mark.parametrize("zeros", [False, True])
def test_a_device_sending_only_garbage_gets_a_hint(tmp_path, man, zeros):
    """Bytes and not one frame: the summary said only "0 samples ... damaged N frames". It says what came
    and what to check: no delimiter at all points at the baud rate, segments at another layout too."""
    junk = np.random.default_rng(3).integers(1, 256, 20_000, dtype=np.uint8)
    if zeros:
        junk[::97] = 0
    res = record_loop(man, tmp_path / "junk.acnlog", junk.tobytes(), baud=115200, duration=1.0)
    (hint,) = [w for w in res.warnings if "baud" in w]
    assert "\n" not in hint and "now 115200" in hint and "20000 bytes" in hint
    assert ("none a frame of this manifest" in hint) == zeros and ("no frame delimiter" in hint) != zeros


def _pty():
    import tty

    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def test_kill_9_mid_stream_loses_at_most_the_last_tenth_of_a_second(tmp_path, manifest_file, telemetry, man):
    master, slave, name = _pty()
    out = tmp_path / "kill.acnlog"
    proc = _start_recorder(tmp_path, manifest_file, name, out)
    frames = split_frames(telemetry)
    sent: list = []
    stop = threading.Event()
    feeder = threading.Thread(target=_feeder, args=(master, frames, 1000.0, sent, stop))
    feeder.start()
    time.sleep(1.2)
    t_kill = time.monotonic()
    proc.send_signal(signal.SIGKILL)
    proc.wait(10)
    stop.set()
    feeder.join()
    os.close(master)
    os.close(slave)
    d = decode_log(out)  # readable after kill -9
    s = d.frames["sample"]
    before = [k for t, k in sent if t < t_kill]
    assert len(before) > 500
    assert d.stats["crc_errors"] == 0 and d.stats["lost"] == 0
    np.testing.assert_array_equal(s["seq"], np.arange(len(s)))  # a clean prefix of what was sent
    last_kept_t = next(t for t, k in sent if k == len(s) - 1)
    lost_s = t_kill - last_kept_t
    print(f"\nkill -9: {len(before)} frames sent before the kill, {len(s)} in the log, last {lost_s * 1e3:.0f} ms lost")
    assert lost_s < 0.1 + 0.15  # flush interval + scheduling slack on a loaded CI machine


def test_pulled_cable_for_good_closes_the_log_cleanly(tmp_path, manifest_file, telemetry):
    master, slave, name = _pty()
    out = tmp_path / "pulled.acnlog"
    proc = _start_recorder(tmp_path, manifest_file, name, out, "--give-up-after", "1")
    os.close(slave)
    frames = split_frames(telemetry)[:300]
    os.write(master, b"".join(frames))
    time.sleep(0.5)
    os.close(master)  # the cable is pulled
    stdout, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 1, (stdout, stderr)
    assert b"link lost" in stdout
    d = decode_log(out)
    assert len(d.frames["sample"]) == 300 and d.torn_bytes == 0


# --------------------------------------------------------------------------
# a link that goes away and comes back: a TCP server on 127.0.0.1 (pyserial's socket://)


def test_recorder_reconnects_and_records_the_gap(tmp_path, man, telemetry):
    frames = split_frames(telemetry)
    # the second connection starts with 50 frames the first one carried (an adapter's buffer replayed)
    url, th, _ = server([b"".join(frames[:500]), b"".join(frames[450:500] + frames[700:])], down_s=2.0)
    shown = io.StringIO()
    out = tmp_path / "reconnect.acnlog"
    rec = Recorder(url, out, man, commands=(("info", {}),), status=Status(shown, enabled=False))
    res = rec.run(max_frames=1800, duration=60)
    rec.close()
    th.join(30)
    assert res.reason == "frames", (res.reason, shown.getvalue())
    assert len(res.gaps) == 1, res.gaps
    g = res.gaps[0]
    assert (g["index_before"], g["index_after"], g["frames_lost"]) == (499, 700, 200)
    assert g["attempts"] >= 2 and g["back_s"] - g["lost_s"] >= 0.5  # refused while the port was closed
    text = shown.getvalue()
    assert "link lost" in text and "retrying socket://127.0.0.1" in text and "link back after" in text
    assert "sample index 499 -> 700, 200 frames lost" in text
    d = decode_log(out)  # one log across the outage
    np.testing.assert_array_equal(d.frames["sample"]["index"], np.r_[0:500, 700:2000])
    assert (d.stats["lost"], d.stats["duplicates"], d.stats["crc_errors"]) == (200, 50, 0)
    assert res.stats["lost"] == 200 and res.stats["duplicates"] == 50
    print(f"\nreconnect: {g}")


def test_damage_at_outages_is_counted_as_the_log_counts_it(tmp_path, man, telemetry):
    """Each connection ends inside a frame and the next begins inside one: the recorder refused the torn end
    at each outage and then the torn start (5 damaged frames over two outages), the log reads both as one
    segment (3). The recorder now counts what the log holds, one way."""
    f = split_frames(telemetry)
    parts = [
        b"".join(f[:300]) + f[300][:20],
        f[310][30:] + b"".join(f[311:600]) + f[600][:10],
        f[605][5:] + b"".join(f[606:]),
    ]
    url, th, _ = server(parts, down_s=0.3)
    out = tmp_path / "outages.acnlog"
    rec = Recorder(url, out, man, commands=(), status=Status(io.StringIO(), enabled=False))
    res = rec.run(max_frames=300 + len(f[311:600]) + len(f[606:]), duration=60)
    rec.close()
    th.join(30)
    assert len(res.gaps) == 2, res.gaps
    d = decode_log(out)
    keys = ("bad_frames", "garbage_bytes", "crc_errors", "lost", "duplicates")
    assert {k: res.stats[k] for k in keys} == {k: d.stats[k] for k in keys}
    assert d.stats["bad_frames"] == 2  # one joined segment per outage


def test_status_line_says_the_link_is_being_retried(man):
    st = Status(io.StringIO(), enabled=True)
    st.note = "link lost 1.2 s ago: retrying socket://x (attempt 3 in 0.4 s)"
    assert st.line(5.0, None).endswith("link lost 1.2 s ago: retrying socket://x (attempt 3 in 0.4 s)")


def test_ctrl_c_while_the_link_is_away_closes_cleanly(tmp_path, manifest_file, telemetry):
    frames = split_frames(telemetry)
    url, th, served = server([b"".join(frames[:300])], down_s=0)
    out = tmp_path / "ctrl_c.acnlog"
    proc = _start_recorder(tmp_path, manifest_file, url, out)
    deadline = time.monotonic() + 30
    while not served:  # the first connection is over: the recorder is retrying
        assert time.monotonic() < deadline and proc.poll() is None
        time.sleep(0.05)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=30)
    th.join(5)
    assert proc.returncode == 0, (stdout, stderr)
    assert b"(stopped)" in stdout and b"link lost at" in stdout and b"not back" in stdout
    assert b"retrying socket://127.0.0.1" in stderr and b"Traceback" not in stderr
    d = decode_log(out)
    assert len(d.frames["sample"]) == 300 and d.torn_bytes == 0
