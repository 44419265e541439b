"""The README's recording walk-through, run as written from an empty folder (a wheel user's: no build/ tree
beside it) against the host firmware's telemetry over a pty: it named build/firmware/gen/.../acnframe.json,
which only a checkout that had built the firmware has."""

from __future__ import annotations

import os
import shlex
import shutil
import subprocess
import sys
import time
import tty

import numpy as np
from conftest import REPO

from accelnav.data.runfile import load_run
from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.model.load import DEFAULT_MODEL

N = 600


def _readme_commands() -> list[list[str]]:
    """The README's `accelnav record` line and the `accelnav log` commands after it, comments dropped."""
    lines = (REPO / "README.md").read_text().splitlines()
    k = next(i for i, x in enumerate(lines) if x.startswith("accelnav record "))
    cmds = []
    for x in lines[k : k + 6]:
        if x.startswith(("accelnav record ", "accelnav log ")):
            for part in x.split("#")[0].split(";"):
                cmds.append(shlex.split(part)[1:])
    return cmds


def test_readme_recording_walk_through_from_an_empty_folder(tmp_path):
    cmds = _readme_commands()
    record, rest = cmds[0], cmds[1:]
    assert record[0] == "record" and [c[:2] for c in rest] == [["log", "info"], ["log", "export"]], cmds
    shutil.copy(DEFAULT_MODEL, tmp_path / "my_sensor.toml")  # the user's model (the README's name for it)

    man = manifest(None)
    fw = HostFirmware(build_firmware(None))  # power-on: the compact mode
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(6).integers(-60, 60, (N, 2))))
    fw.rx(encode_command(man, "flush"))
    telemetry = fw.take()

    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    port = [a if not a.startswith("socket://") else os.ttyname(slave) for a in record]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    accelnav = [sys.executable, "-m", "accelnav.cli"]
    proc = subprocess.Popen([*accelnav, *port, "--duration", "4"], cwd=tmp_path, env=env, stdout=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while not (tmp_path / "run.acnlog").exists():  # the header is written once the port is open
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.02)
    os.write(master, telemetry)
    out, _ = proc.communicate(timeout=60)
    os.close(master)
    os.close(slave)
    assert proc.returncode == 0 and f"{N} samples, lost 0".encode() in out, out
    for c in rest:
        done = subprocess.run([*accelnav, *c], cwd=tmp_path, env=env, capture_output=True, timeout=60)
        assert done.returncode == 0, (c, done.stdout, done.stderr)
    arrays, _ = load_run(tmp_path / "run.npz")
    np.testing.assert_array_equal(arrays["fw_index"], np.arange(N))
