"""The recorder's live line tells the truth from the first second, in both wire formats: a socket serves the
host firmware's own telemetry at a known sample rate, and every status line after 1 s is checked against it
(it read "0 frames" for a compact stream without model text, and with one the rate swung between 0 and
~2.5x the true rate as rows waited for checkpoints; pyserial's socket open dropped the first block, which
the compact replay then counted as a checkpoint interval lost)."""

from __future__ import annotations

import io
import re
import socket
import threading
import time

import numpy as np
import pytest

from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.recorder import Recorder, Status
from accelnav.model.load import load_model

RATE = 200.0  # samples/s served
SECONDS = 2.5
LINE = re.compile(r"^\s*([\d.]+) s\s+([\d.]+) frames/s\s+(\d+) frames\s+lost (\d+)")


def _chunks(mode: str) -> list[bytes]:
    """The firmware's bytes after each sample, from power-on (in the state mode after its ack)."""
    man = manifest(None)
    fw = HostFirmware(build_firmware(None))
    if mode == "states":
        fw.rx(encode_command(man, "mode_states"))
        fw.take()
    n = int(RATE * (SECONDS + 0.5))
    code = 2048 + np.random.default_rng(4).integers(-60, 60, (n, 2))
    out = []
    for k in range(n):
        fw.rx(encode_stimulus(man, code=code[k : k + 1]))
        out.append(fw.take())
    return out


def _serve(chunks: list[bytes]):
    """A device on a socket: it starts sending on connection, one sample's bytes every 1/RATE s."""
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)

    def run():
        conn, _ = srv.accept()
        t0 = time.monotonic()
        for k, data in enumerate(chunks):
            time.sleep(max(0.0, t0 + k / RATE - time.monotonic()))
            try:
                conn.sendall(data)
            except OSError:  # the recorder's duration ended first
                break
        conn.close()
        srv.close()

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return f"socket://127.0.0.1:{srv.getsockname()[1]}", th


@pytest.mark.parametrize("mode,with_model", [("states", False), ("compact", True), ("compact", False)])
def test_live_line_counts_frames_rate_and_losses_as_served(tmp_path, mode, with_model):
    man = manifest(None)
    url, th = _serve(_chunks(mode))
    shown = io.StringIO()
    text = load_model().text if with_model else ""
    rec = Recorder(url, tmp_path / "live.acnlog", man, commands=(), model_text=text, status=Status(shown, True))
    res = rec.run(duration=SECONDS)
    rec.close()
    lines = [LINE.match(x) for x in shown.getvalue().replace("\r", "\n").splitlines()]
    rows = [tuple(float(g) for g in m.groups()) for m in lines if m]
    late = [r for r in rows if r[0] >= 1.0]
    assert len(late) >= 4, shown.getvalue()
    B = man.data["block_samples"] if mode == "compact" else 1  # the compact stream arrives a block at a time
    for t, rate, frames, lost in late:
        assert abs(rate - RATE) <= 0.05 * RATE, (t, rate)
        assert lost == 0, (t, lost)
        # what the device had sent by then, less at most a block in flight and the scheduling slack
        assert RATE * (t - 0.3) - B <= frames <= RATE * (t + 0.1), (t, frames)
    if with_model or mode == "states":  # every sample received is a row at the end, none lost
        assert res.stats["frames"]["sample"] == rows[-1][2] and res.stats["lost"] == 0
    else:
        assert res.stats["unreplayed"] == rows[-1][2]
    th.join(5)
