"""SIL and PIL: the same firmware in-process and on the emulated Cortex-M3, bit for bit.

The PIL tests need qemu-system-arm and arm-none-eabi-gcc. Where they are
missing the tests skip and say why; with ACCELNAV_REQUIRE_PIL=1 (set by
.ci/run) a missing tool is a failure instead, so CI cannot pass by skipping.
"""

from __future__ import annotations

import os
import shutil
import subprocess

import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.codegen.model import load_model
from accelnav.hil_sim import hil, qemu
from accelnav.hil_sim.firmware import manifest
from accelnav.hil_sim.sensor import simulate

SIGMA_FRACTION = 1e-3  # firmware vs float64 reference, in units of the reference's sigma, after 1 s


def _require_pil():
    missing = [tool for tool in ("qemu-system-arm", "arm-none-eabi-gcc") if shutil.which(tool) is None]
    if missing:
        reason = f"PIL needs {', '.join(missing)} (Debian: qemu-system-arm gcc-arm-none-eabi libnewlib-arm-none-eabi)"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but {reason}")
        pytest.skip(reason)


@pytest.mark.parametrize(
    "model_file,scenario,seconds",
    [
        ("adxl250_default.toml", "stop_and_go", 12.0),
        ("adxl250_default.toml", "shock", 4.0),  # rail-clipped samples: predict-only steps on both targets
        ("adxl202_duty.toml", "vehicle", 10.0),
        ("adxl202_duty.toml", "sinusoid", 6.0),
    ],
)
def test_pil_frames_equal_sil_bit_for_bit(tmp_path, model_file, scenario, seconds):
    _require_pil()
    model = load_model(MODELS / model_file)
    run = simulate(model, scenario, seconds, seed=9)
    man = manifest(model.source)
    stim = hil.stimulus(man, run)
    sil = hil.run_sil(model, stim)
    pil = hil.run_pil(model, stim, len(run.t), tmp_path / "pil.acnlog")
    c = hil.compare(model, run, sil, pil.telemetry)
    assert c.n == len(run.t)
    assert c.pil_equal_sil, f"PIL differs from SIL from frame {c.first_difference}"
    if scenario == "shock":
        assert run.clipped.any()
    for key, err in c.max_err_sigma.items():
        assert err < SIGMA_FRACTION, f"{key}: firmware off the float64 reference by {err:.2e} sigma"
    assert c.max_of_bound <= 1.0, f"firmware at {c.max_of_bound:.3g} of the generator's stated bound"
    assert pil.stats["lost"] == 0 and pil.stats["crc_errors"] == 0


def test_sil_agrees_with_reference_and_compare_catches_a_flipped_bit(default_model):
    run = simulate(default_model, "stop_and_go", 8.0, seed=2)
    man = manifest(default_model.source)
    sil = hil.run_sil(default_model, hil.stimulus(man, run))
    c = hil.compare(default_model, run, sil, sil)
    assert c.pil_equal_sil and c.first_difference is None
    assert max(c.max_err_sigma.values()) < SIGMA_FRACTION and c.max_of_bound <= 1.0
    # one bit of one state in frame 500, re-framed with a valid CRC: must be seen
    from accelnav.link.telemetry import decode_all, encode_frames

    frames, _ = decode_all(man, sil)
    samples = frames["sample"].copy()
    samples[500]["x.r"] ^= 1
    tampered = encode_frames(man, "sample", samples)
    c = hil.compare(default_model, run, sil, tampered)
    assert c.pil_equal_sil is False and c.first_difference == 500


def test_smoother_with_zupt_beats_filter_in_the_summary(default_model):
    run = simulate(default_model, "stop_and_go", 30.0, seed=4)
    man = manifest(default_model.source)
    c = hil.compare(default_model, run, hil.run_sil(default_model, hil.stimulus(man, run)))
    final = {(row.axis, row.method): abs(row.final) for row in c.position_rows}
    for axis in run.axis_names:
        assert final[(axis, "smoother + ZUPT")] < 0.1 * final[(axis, "firmware filter")]


def test_qemu_is_never_left_behind(tmp_path):
    _require_pil()
    elf = hil.make_firmware("mps2_an385") / "accelnav_fw.elf"
    with pytest.raises(RuntimeError, match="inside"):
        with qemu.Mps2Board(elf) as board:
            board.open(0)
            pid = board.proc.pid
            raise RuntimeError("an error inside the run")
    assert board.proc.poll() is not None
    ps = subprocess.run(["ps", "-p", str(pid), "-o", "stat="], capture_output=True, text=True).stdout.strip()
    assert ps in ("", "Z"), f"qemu process {pid} still there: {ps!r}"


def test_missing_emulator_is_a_clear_error(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(qemu.shutil, "which", lambda name: None)
    with pytest.raises(qemu.QemuError, match="qemu-system-arm not found: install"):
        qemu.require_qemu()
    (tmp_path / "fw.elf").write_bytes(b"\x7fELF")
    with pytest.raises(qemu.QemuError, match="not found"):
        qemu.Mps2Board(tmp_path / "fw.elf")
    with pytest.raises(qemu.QemuError, match="no firmware image"):
        qemu.Mps2Board(tmp_path / "missing.elf")


def test_hil_cli_sil(tmp_path, capsys):
    status = main(["hil", "--target", "sil", "--duration", "6", "--plots", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0
    assert "firmware vs float64 reference" in out and "smoother + ZUPT" in out
    assert (tmp_path / "hil.png").stat().st_size > 10_000
    status = main(["hil", "--scenario", "nowhere"])
    assert status == 2 and "unknown scenario" in capsys.readouterr().err


def _schedule_model(tmp_path):
    from accelnav.codegen.model import load_model as load

    text = (MODELS / "adxl250_default.toml").read_text().replace('form = "covariance" ', 'form = "gain_schedule" ')
    path = tmp_path / "gs.toml"
    path.write_text(text)
    model = load(path)
    assert model.filter.form == "gain_schedule"
    return model


def test_stated_bound_is_against_the_kalman_filter_and_catches_a_blind_schedule(tmp_path, capsys):
    """The time-indexed schedule ignores skipped samples. Forced past the generator's refusal onto a
    shock run (rail-clipped samples), its departure from the float64 Kalman filter must exceed the
    stated bound, which hil.compare uses; the refusal itself reaches `accelnav hil` as one line."""
    import numpy as np

    from accelnav.codegen.design import axis_design
    from accelnav.codegen.emit_c import emit
    from accelnav.codegen.harness import AxisRunner, build
    from accelnav.estimate.kf import run_filter

    model = _schedule_model(tmp_path)
    run = simulate(model, "shock", 4.0, seed=9)
    valid = ~run.clipped[:, 0]
    assert not valid.all()
    files = emit(model, assume_no_skips=True)
    res = AxisRunner(build(files, tmp_path / "c"), files["accelnav.json"], 0).run(code=run.code[:, 0])
    kf = run_filter(axis_design(model, 0), run.accel[:, 0], valid=valid, progress=False)
    bound = hil.stated_bound(model, 0, run, kf.x_post)
    assert (np.abs(res["x"] - kf.x_post) / bound).max() > 1.0
    status = main(["hil", "--model", str(tmp_path / "gs.toml"), "--target", "sil", "--duration", "2"])
    err = capsys.readouterr().err.strip()
    assert status != 0 and len(err.splitlines()) == 1 and "'gain_schedule' refused" in err


@pytest.mark.parametrize("rate", [1000.0])  # 100 Hz: test_pil_frames_equal_sil_bit_for_bit[shock]
def test_sil_shock_against_the_float64_filter(tmp_path, rate):
    """The firmware in-process on rail-clipped shock data at 1 kHz: within the stated bound of the
    float64 Kalman filter (same skips) at every sample, and < 1e-3 of its sigma after 1 s."""
    from accelnav.codegen.model import load_model as load

    text = (MODELS / "adxl250_default.toml").read_text().replace("rate_hz = 100.0", f"rate_hz = {rate!r}")
    path = tmp_path / "fast.toml"
    path.write_text(text)
    model = load(path)
    run = simulate(model, "shock", 3.0, seed=9)
    assert run.clipped.any()
    man = manifest(model.source)
    c = hil.compare(model, run, hil.run_sil(model, hil.stimulus(man, run)))
    assert c.max_of_bound <= 1.0, f"firmware at {c.max_of_bound:.3g} of the generator's stated bound"
    for key, err in c.max_err_sigma.items():
        assert err < SIGMA_FRACTION, f"{key}: firmware off the float64 reference by {err:.2e} sigma"
