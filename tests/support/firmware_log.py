"""A recorder log of the host-built firmware's telemetry, as `accelnav record` writes it (with --model, or
with --manifest alone: no model text in it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from accelnav.hil_sim.targets.firmware import HostFirmware, build_firmware, manifest
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.logfile import LogWriter
from accelnav.model.load import load_model


def firmware_log(path: Path, mode: str, with_model: bool, n: int) -> Path:
    """``n`` samples of the firmware in ``mode`` (states or compact) logged at ``path``."""
    man = manifest(None)
    fw = HostFirmware(build_firmware(None))
    if mode == "states":
        fw.rx(encode_command(man, "mode_states"))
        fw.take()
    fw.rx(encode_stimulus(man, code=2048 + np.random.default_rng(5).integers(-60, 60, (n, 2))))
    fw.rx(encode_command(man, "flush"))  # the last partial block and a checkpoint: every sample sent
    meta = {"manifest": man.data, "model_toml": load_model().text if with_model else "", "source": "test"}
    with LogWriter(path, meta, fsync_s=None) as log:
        log.append(fw.take())
    return path
