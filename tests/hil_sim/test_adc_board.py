"""PIL on a board whose samples come from an emulated peripheral: netduino2 (STM32F205 in QEMU).

TIM3's update interrupt starts the conversions, the firmware reads ADC1's data register, runs the
generated filters and streams on USART1; QEMU writes that UART to a file. The codes the firmware read
are taken from its own frames, SIL runs on them, and the two telemetry streams must be the same bytes.

Needs qemu-system-arm and arm-none-eabi-gcc: skipped with the reason without them, a failure under
ACCELNAV_REQUIRE_PIL=1 (CI).
"""

from __future__ import annotations

import os
import shutil
import subprocess

import numpy as np
import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.hil_sim.targets import hil, qemu
from accelnav.hil_sim.targets.firmware import generated, manifest, private_firmware
from accelnav.link.codec import encode_stimulus
from accelnav.link.decoder import decode_all, replay_for
from accelnav.link.logfile import read_log
from accelnav.model.load import load_model
from accelnav.resources import firmware_dir

QEMU_ADC_STEP = 7  # QEMU's STM32F2 ADC model: each DR read after SWSTART returns the last value + 7


def _require_pil():
    missing = [tool for tool in ("qemu-system-arm", "arm-none-eabi-gcc") if shutil.which(tool) is None]
    if missing:
        reason = f"PIL on netduino2 needs {', '.join(missing)} (Debian: qemu-system-arm gcc-arm-none-eabi)"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but {reason}")
        pytest.skip(reason)


@pytest.fixture(scope="module")
def model():
    return load_model(MODELS / "adxl250_default.toml")  # 2 axes, 12-bit ADC, 100 Hz


# 2 n conversions: the ramp passes full scale (4095 = 585 x 7, a rail the filter refuses) and wraps;
# compact mode: 20 block frames and checkpoints every 256 samples; states: a sample frame each (320)
@pytest.mark.parametrize(("commands", "n"), [((), 640), (("mode_states",), 320)], ids=["compact", "states"])
def test_netduino2_adc_pil_equals_sil(model, commands, n):
    _require_pil()
    res = hil.run_adc_pil(model, n, commands=commands)
    # the firmware read QEMU's ADC: one conversion per axis per sample, in channel order
    expect = (QEMU_ADC_STEP * np.arange(1, 2 * n + 1)) % 4096
    assert np.array_equal(res.codes.ravel(), expect), "the codes are not the emulated ADC's sequence"
    assert (res.codes == 4095).any()
    man = manifest(model.source)
    frames, st = decode_all(man, res.telemetry, replay_for(man, model))
    if commands:
        assert len(frames["ack"]) == 1 and len(frames.get("block", ())) == 0  # sample frames, states each
    else:
        assert len(frames["block"]) == n // man.data["block_samples"] and st.mismatches == 0
        assert len(frames["checkpoint"]) >= 2 * 3  # power-on, 256, 512; per axis
    assert st.lost == 0 and st.bad_frames == 0
    assert res.equal, f"PIL and SIL telemetry differ from byte {res.first_difference}"
    assert res.telemetry == res.sil


def test_netduino2_comparison_sees_one_code_changed(model):
    """The same comparison, with SIL fed one code off by one: the streams must differ."""
    _require_pil()
    res = hil.run_adc_pil(model, 64, commands=("mode_states",))
    assert res.equal
    codes = res.codes.copy()
    codes[40, 1] += 1
    man = manifest(model.source)
    stim = b"".join(hil.encode_command(man, c) for c in ("mode_states",)) + encode_stimulus(man, code=codes)
    assert hil.run_sil(model, stim) != res.telemetry


def test_adc_board_errors_are_one_line(tmp_path):
    with pytest.raises(qemu.QemuError, match="accepted: netduino2"):
        qemu.run_adc(tmp_path / "x.elf", "mps2_an385", 10)
    with pytest.raises(ValueError, match="periods"):
        qemu.run_adc(tmp_path / "x.elf", "netduino2", 0)
    _require_pil()
    with pytest.raises(qemu.QemuError, match="no firmware image"):
        qemu.run_adc(tmp_path / "x.elf", "netduino2", 10)


def test_netduino2_real_part_variant_compiles(tmp_path, model):
    """The emulated build sets ACN_STM32_QEMU; the part's code paths (ready flags and EOC waited for, TXE
    interrupt) are compiled here with the same strict flags, so they cannot rot unseen."""
    _require_pil()
    for name, text in generated(str(model.source)).items():
        (tmp_path / name).write_text(text)
    boards = firmware_dir() / "boards"
    cmd = ["arm-none-eabi-gcc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-mcpu=cortex-m3", "-mthumb",
           "-ffreestanding", "-fsyntax-only", f"-I{boards / 'netduino2'}", f"-I{boards}",
           f"-I{firmware_dir() / 'src'}", f"-I{tmp_path}", str(boards / "netduino2" / "board_netduino2.c"),
           str(boards / "stm32_rt.c")]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_hil_cli_pil_on_the_adc_board(tmp_path, capsys):
    _require_pil()
    status = main(["hil", "--target", "pil", "--board", "netduino2", "--duration", "3.2", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0, out
    assert "320 sample periods on netduino2" in out
    assert "PIL vs SIL on those codes: 320 samples, bit-identical" in out
    log = tmp_path / "pil_netduino2_adxl250_default_adc.acnlog"
    assert b"".join(read_log(log).data) == hil.run_adc_pil(load_model(None), 320).telemetry  # the same run again


def test_hil_cli_adc_board_refuses_a_scenario_and_a_duty_model(tmp_path, capsys):
    assert main(["hil", "--target", "pil", "--board", "netduino2", "--scenario", "shock"]) == 2
    assert "--scenario: not with --board netduino2" in capsys.readouterr().err
    duty = ["hil", "--target", "pil", "--board", "netduino2", "--model", str(MODELS / "adxl202_duty.toml")]
    assert main([*duty, "--out", str(tmp_path)]) == 2
    assert "samples an ADC; the model's sensor is duty_cycle" in capsys.readouterr().err


def test_netduino2_answers_info_with_its_board_id(model):
    """A command before the sample clock starts is answered through USART1, naming the board."""
    _require_pil()
    man = manifest(model.source)
    with private_firmware("netduino2", model.source) as fw:
        tel = qemu.run_adc(fw / "accelnav_fw.elf", "netduino2", 32, hil.encode_command(man, "info"))
    frames, _ = decode_all(man, tel)
    assert len(frames["info"]) == 1 and len(frames["block"]) == 1
    assert frames["info"]["board"][0] == man.data["boards"]["netduino2"]
