"""Every file accelnav writes reads back into every command that reads a recording, without reader flags
(issue 33): sim's run file and CSV, smooth's and filter's outputs with their input, a recorder log and its
CSV and NPZ exports, each into fit-bias, calibrate, tune, smooth, filter and hil --input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from support.cli import run_cli

from accelnav.cli import main
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.logfile import LogWriter
from accelnav.model.load import load_model

# the scenario each command's job needs: still for the bias fit, still poses for calibrate, a run with rests
SCENARIO = {"fit-bias": "stationary", "calibrate": "tumble", "tune": "stop_and_go", "smooth": "stop_and_go",
            "filter": "stop_and_go", "hil": "stop_and_go"}  # fmt: skip
DURATION = {"stationary": 61, "tumble": 61, "stop_and_go": 30}
FILES = ("sim.npz", "sim.csv", "smooth_full.npz", "smooth_full.csv", "filter.npz", "filter.csv", "rec.acnlog",
         "log.csv", "log.npz")  # fmt: skip


def _log(sim: Path, path: Path) -> Path:
    """A recorder log of the host-built firmware fed the simulation's ADC codes, as `accelnav record` writes it."""
    man = manifest(None)
    fw = HostFirmware(build_firmware(None))
    fw.rx(encode_stimulus(man, code=np.load(sim)["code"]))
    fw.rx(encode_command(man, "flush"))
    with LogWriter(path, {"manifest": man.data, "model_toml": load_model().text, "source": "test"}, fsync_s=None) as w:
        w.append(fw.take())
    return path


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, Path]:
    """Each scenario's files as accelnav writes them, in a folder per scenario."""
    folders = {}
    for scenario, seconds in DURATION.items():
        d = tmp_path_factory.mktemp(scenario)
        steps = [
            ["sim", "--scenario", scenario, "--duration", seconds, "--out", d / "sim.npz", "--csv", d / "sim.csv"],
            ["smooth", d / "sim.npz", "--full", "--out", d / "smooth_full.npz", "--csv", d / "smooth_full.csv"],
            ["smooth", d / "sim.npz", "--out", d / "smooth.npz", "--csv", d / "smooth.csv"],
            ["filter", d / "sim.npz", "--out", d / "filter.npz", "--csv", d / "filter.csv"],
        ]
        for argv in steps:
            assert main([str(a) for a in argv]) == 0
        _log(d / "sim.npz", d / "rec.acnlog")
        for out in ("log.csv", "log.npz"):
            assert main(["log", "export", str(d / "rec.acnlog"), "--out", str(d / out)]) == 0
        folders[scenario] = d
    return folders


@pytest.mark.parametrize("name", FILES)
@pytest.mark.parametrize("command", list(SCENARIO))
def test_every_command_reads_every_file_accelnav_writes(written, tmp_path, capsys, command, name):
    path = written[SCENARIO[command]] / name
    argv = [command, "--input", path] if command == "hil" else [command, path]
    out = tmp_path / ("out" if command == "hil" else "out.toml" if command in ("fit-bias", "calibrate", "tune")
                      else "out.npz")  # fmt: skip
    argv += ["--out", out]
    if command == "tune":
        argv += ["--zupt", "auto", "--max-evaluations", "10"]
    status, stdout, stderr = run_cli(argv, capsys)
    assert status == 0, (stderr or stdout).strip().splitlines()[-1]


@pytest.mark.parametrize("name", ["smooth.npz", "smooth.csv"])
def test_an_output_without_its_input_is_refused_saying_so(written, tmp_path, capsys, name):
    path = written["stop_and_go"] / name
    for command in ("smooth", "fit-bias"):
        status, _, err = run_cli([command, path, "--out", tmp_path / "o.toml"], capsys)
        assert status == 2
        assert err.strip() == (
            f"accelnav: error: {path}: an estimator's output without its input (positions and velocities, no "
            "acceleration): read the recording it was made from, or write the output with --full to keep the "
            "input in it"
        )
