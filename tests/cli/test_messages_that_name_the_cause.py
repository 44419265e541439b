"""Messages that named a symptom instead of the cause (issue 30): each case gives one line that says what is
wrong with what was given. Logs are written in a temporary folder from the firmware's own telemetry."""

from __future__ import annotations

import numpy as np
import pytest
from support.cli import run_cli

from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.logfile import LogWriter
from accelnav.model.load import DEFAULT_MODEL
from accelnav.native.cbuild import BuildError
from accelnav.resources import models_dir

DUTY = models_dir() / "adxl202_duty.toml"


def _log(path, man, model_text: str, states: bool):
    fw = HostFirmware(build_firmware(None))
    if states:
        fw.rx(encode_command(man, "mode_states"))
        fw.take()
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(1).integers(-300, 300, (600, 2))))
    fw.rx(encode_command(man, "flush"))
    meta = {"manifest": man.data, "model_toml": model_text, "source": "test", "started_utc": "2026-01-01T00:00:00Z"}
    with LogWriter(path, meta, fsync_s=None) as log:
        log.append(fw.take())
    return path


def _one_line(status, err) -> str:
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    return err.strip()


@pytest.mark.parametrize(
    "cmd",
    [
        ["log", "info", "{log}"],
        ["log", "export", "{log}", "--out", "{tmp}/x.npz"],
        ["log", "plot", "{log}", "--out", "{tmp}/x.png"],
        ["smooth", "{log}", "--out", "{tmp}/s.npz"],
        ["filter", "{log}", "--out", "{tmp}/f.npz"],
        ["tune", "{log}", "--out", "{tmp}/t.toml"],
    ],
)
def test_a_log_whose_model_is_of_another_kind_than_its_frames(man, tmp_path, capsys, cmd):
    """A duty-cycle model in a log of ADC codes: six commands ended in a TypeError from the conversion."""
    log = _log(tmp_path / "mixed.acnlog", man, DUTY.read_text(), states=True)
    argv = [a.format(log=log, tmp=tmp_path) for a in cmd]
    line = _one_line(*run_cli(argv, capsys)[::2])
    assert line == (
        f"accelnav: error: {log}: its model_toml is a duty-cycle part but the log's frames carry ADC codes: "
        "not the model the firmware was built with"
    )


def test_a_model_of_another_kind_given_to_smooth(man, tmp_path, capsys):
    """--model of a duty-cycle part (at 10 Hz) for a log of an analog part: it was refused as "sampled at 100 Hz
    but the model has 10 Hz", and a duty-cycle model at the log's rate was taken silently."""
    log = _log(tmp_path / "adc.acnlog", man, DEFAULT_MODEL.read_text(), states=True)
    for rate in ("10.0", "100.0"):
        duty = tmp_path / f"duty{rate}.toml"
        duty.write_text(DUTY.read_text().replace("rate_hz = 100.0", f"rate_hz = {rate}"))
        line = _one_line(*run_cli(["smooth", log, "--model", duty, "--out", tmp_path / "s.npz"], capsys)[::2])
        assert line == (
            f"accelnav: error: {duty}: a duty-cycle part, but {log} was recorded from an analog part "
            f"({log}:model_toml): give a model of that part"
        )
    assert not (tmp_path / "s.npz").exists()


def test_a_replay_that_cannot_be_built_is_not_reported_as_a_missing_model(man, tmp_path, capsys, monkeypatch):
    """The log carries its model, but the replay could not be made of it (a broken cache, no compiler): the
    message asked for --model, which was there. It says why the replay failed."""
    log = _log(tmp_path / "compact.acnlog", man, DEFAULT_MODEL.read_text(), states=False)

    def broken(*_):
        raise BuildError("cached replay module gen-x.so: invalid ELF header")

    monkeypatch.setattr("accelnav.link.recorder.replay_for", broken)
    line = _one_line(*run_cli(["log", "export", log, "--out", tmp_path / "x.npz"], capsys)[::2])
    assert line == (
        f"accelnav: error: {log}: its 600 samples came in compact frames and no replay of the model could be made "
        "to turn them into rows: cached replay module gen-x.so: invalid ELF header"
    )
    assert "--model" not in line


def test_calibrate_reads_a_log_as_fit_bias_does(man, tmp_path, capsys):
    """A recorder log given to calibrate was read as CSV ("NUL byte"), then refused as a log; it now goes
    through the one reader every command uses: what is left to say is about its poses, not its format."""
    log = _log(tmp_path / "still.acnlog", man, DEFAULT_MODEL.read_text(), states=True)
    line = _one_line(*run_cli(["calibrate", log, "--out", tmp_path / "c.toml"], capsys)[::2])
    assert line.startswith(f"accelnav: error: {log}: pose 1 at ")
    assert "not a recording" not in line and "NUL" not in line
