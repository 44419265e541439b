"""The live plot, headless: a recorded stream of the host firmware drawn through the recorder's hook and
replayed from its log; the figure's axes and lines checked, the PNG written under the test's tmp dir."""

from __future__ import annotations

import threading
import urllib.request

import numpy as np
import pytest
import serial

from accelnav.cli import main as cli_main
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.manifest import sample_columns
from accelnav.link.recorder import Recorder, Status, decode_log
from accelnav.model import input_conversion
from accelnav.model.load import load_model
from accelnav.plots.live import LivePlot, LiveView, plot_log

N = 1500
SECONDS = 4.0  # the ring holds fewer samples than the stream: the plot shows only its end


@pytest.fixture(scope="module")
def telemetry(man):
    """The default model's firmware (host board, cffi) in the state mode: 1500 samples of noise with a push
    on x (+10 codes for 1 s, then -10 for 1 s), so that the position estimate moves."""
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_command(man, "mode_states"))
    fw.take()  # the ack
    code = 2048 + np.random.default_rng(25).integers(-3, 4, (N, 2))
    code[600:700, 0] += 10  # push, then brake: x moves and comes to rest
    code[700:800, 0] -= 10
    fw.rx(encode_stimulus(man, code=code))
    return fw.take()


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, man, telemetry):
    """The stream recorded over loop:// with a live plot fed by the recorder: (log path, live plot)."""
    out = tmp_path_factory.mktemp("live") / "bench.acnlog"
    model = load_model()
    plot = LivePlot(man, model, seconds=SECONDS)
    port = serial.serial_for_url("loop://", timeout=0.02)
    writer = threading.Thread(target=port.write, args=(telemetry,), daemon=True)
    rec = Recorder(port, out, man, commands=(), model_text=model.text, status=Status(enabled=False), on_rows=plot.push)
    writer.start()
    res = rec.run(max_frames=N, duration=30)
    rec.close()
    writer.join(5)
    assert res.reason == "frames" and res.stats["lost"] == 0
    return out, plot


def test_live_plot_from_a_recorded_stream(recorded, man, tmp_path):
    log, plot = recorded
    cols = sample_columns(man, decode_log(log).frames["sample"])
    assert plot.pushed == N and plot.capacity == round(SECONDS * man.rate_hz) < N
    fig = plot.figure()
    ax_a, ax_r = fig.axes
    assert ax_a.get_title() == "raw acceleration [m/s^2]"
    assert ax_r.get_title() == "firmware position estimate r [m]"
    model = load_model()
    for j, name in enumerate(man.axes):
        acc, pos = ax_a.get_lines()[j], ax_r.get_lines()[j]
        assert acc.get_label() == pos.get_label() == name
        assert len(acc.get_xdata()) == len(pos.get_ydata()) == plot.capacity
        # the newest sample on the right: the log's last time, firmware r and converted raw input
        np.testing.assert_array_equal(pos.get_xdata(), cols["t"][-plot.capacity :])
        np.testing.assert_array_equal(pos.get_ydata(), cols["r"][-plot.capacity :, j])
        assert pos.get_ydata()[-1] == cols["r"][-1, j]
        conv = input_conversion(model, j)
        np.testing.assert_array_equal(acc.get_ydata(), conv.accel(cols["code"][-plot.capacity :, j]))
        assert np.ptp(pos.get_ydata()) > 0 and np.ptp(acc.get_ydata()) > 0  # not a blank picture
    png = plot.save(tmp_path / "live.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    print(f"live plot: {png}")


def test_log_plot_replays_through_the_same_drawing(recorded, tmp_path, capsys):
    log, live = recorded
    out = tmp_path / "replayed.png"
    replayed = plot_log(log, out, seconds=SECONDS)
    for a, b in zip(live.snapshot(), replayed.snapshot(), strict=True):
        np.testing.assert_array_equal(a, b)
    assert cli_main(["log", "plot", str(log), "--out", str(tmp_path / "cli.png")]) == 0
    assert "the last 1000 of 1500 samples" in capsys.readouterr().out
    assert (tmp_path / "cli.png").read_bytes()[:4] == b"\x89PNG"


def test_log_plot_refusals_are_one_line(recorded, tmp_path, capsys):
    log, _ = recorded
    assert cli_main(["log", "plot", str(log), "--out", str(tmp_path / "x.jpg")]) != 0
    assert cli_main(["log", "plot", str(log), "--out", str(tmp_path / "x.png"), "--seconds", "0"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "accepted: a .png file name" in err[0] and "--seconds" in err[1], err
    assert not list(tmp_path.iterdir())


def test_live_view_draws_from_its_thread_and_serves_the_page(man, recorded, tmp_path):
    log, _ = recorded
    rows = decode_log(log).frames["sample"]
    plot = LivePlot(man, None, seconds=SECONDS)  # no model: the raw codes as they came
    view = LiveView(plot, tmp_path / "bench.acnlog.live.png", interval_s=0.05, port=0).start()
    try:
        plot.push(rows[:300])  # returns at once: the drawing is the thread's
        assert plot.pushed == 300
        page = urllib.request.urlopen(view.url, timeout=5).read().decode()
        assert 'http-equiv="refresh"' in page and 'src="live.png"' in page
        assert view.url.startswith("http://127.0.0.1:")
    finally:
        view.close()
    assert view.frames_drawn >= 1 and view.error is None
    assert plot.figure().axes[0].get_title() == "raw input [code]"
    assert view.png.read_bytes()[:4] == b"\x89PNG"
