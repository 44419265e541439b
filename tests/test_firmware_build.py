"""The firmware builds for all three boards with -Werror, the host board runs as a program, and the
mps2_an385 image runs in qemu-system-arm: telemetry on UART0, stimulus on UART1, both over TCP
(pyserial socket://), bit-identical to the host board. The C is clang-format clean.

Boards needing arm-none-eabi-gcc or qemu-system-arm are skipped, with the reason, where those are
missing; CI (.ci/run) installs them.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from accelnav.hil_sim.firmware import DUTY_MODEL
from accelnav.hil_sim.firmware import make_firmware as build_image
from accelnav.hil_sim.qemu import Mps2Board, qemu_command
from accelnav.link.recorder import Recorder, Status, decode_log
from accelnav.link.telemetry import Decoder, Manifest, decode_all, encode_command, encode_stimulus

REPO = Path(__file__).resolve().parents[1]
STM32_FLASH, STM32_RAM = 64 * 1024, 20 * 1024

needs_arm = pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None, reason="arm-none-eabi-gcc not installed")
needs_qemu = pytest.mark.skipif(shutil.which("qemu-system-arm") is None, reason="qemu-system-arm not installed")


def make_firmware(board: str, model: Path | None = None) -> Path:
    out = build_image(board, model)
    assert (out / "size.txt").is_file()
    return out


def sizes(out: Path) -> dict[str, int]:
    line = (out / "size.txt").read_text().splitlines()[1].split()
    return {"text": int(line[0]), "data": int(line[1]), "bss": int(line[2])}


def test_host_board_builds_and_runs_as_a_program():
    out = make_firmware("host")
    man = Manifest.load(out / "gen" / "acnframe.json")
    code = 2048 + np.random.default_rng(3).integers(-30, 30, (300, 2))
    stdin = encode_command(man, "info") + encode_stimulus(man, code=code)
    done = subprocess.run([out / "accelnav_fw"], input=stdin, capture_output=True, timeout=60)
    assert done.returncode == 0
    frames, stats = decode_all(man, done.stdout)
    assert len(frames["sample"]) == 300 and len(frames["info"]) == 1 and stats.bad_frames == 0
    print(f"\nhost board: {sizes(out)}")


@needs_arm
@pytest.mark.parametrize("model", [None, DUTY_MODEL], ids=["adxl250", "adxl202"])
def test_stm32f103_builds_and_fits(model):
    out = make_firmware("stm32f103", model)
    s = sizes(out)
    print(f"\nstm32f103 ({'default' if model is None else model.stem}): {s}")
    assert s["text"] + s["data"] <= STM32_FLASH
    assert s["data"] + s["bss"] + 2048 <= STM32_RAM  # the linker script also keeps 2 KiB for the stack
    for ext in (".elf", ".bin", ".hex"):
        assert (out / f"accelnav_fw{ext}").stat().st_size > 0
    hdr = subprocess.run(["arm-none-eabi-readelf", "-h", out / "accelnav_fw.elf"], capture_output=True, text=True)
    assert re.search(r"Machine:\s+ARM", hdr.stdout) and re.search(r"Entry point address:\s+0x80", hdr.stdout)
    vec = subprocess.run(
        ["arm-none-eabi-objdump", "-s", "-j", ".isr_vector", out / "accelnav_fw.elf"], capture_output=True, text=True
    ).stdout
    assert " 8000000 00500020 " in vec  # initial SP: the top of the 20 KiB RAM


@needs_arm
def test_mps2_an385_builds():
    out = make_firmware("mps2_an385")
    print(f"\nmps2_an385: {sizes(out)}")
    assert (out / "accelnav_fw.elf").is_file()


def test_firmware_c_is_clang_formatted():
    if shutil.which("clang-format") is None:
        pytest.skip("clang-format not installed")
    ours = [
        *sorted((REPO / "firmware" / "src").glob("*.[ch]")),
        REPO / "firmware" / "boards" / "acn_board.h",
        *sorted((REPO / "firmware" / "boards" / "host").glob("*.[ch]")),
        REPO / "firmware" / "boards" / "mps2_an385" / "board_mps2.c",
        *sorted((REPO / "firmware" / "boards" / "stm32f103").glob("*.[ch]")),
    ]
    done = subprocess.run(["clang-format", "--dry-run", "-Werror", *ours], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]


# --------------------------------------------------------------------------
# QEMU


@needs_arm
@needs_qemu
def test_mps2_an385_in_qemu_matches_the_host_board(tmp_path):
    out = make_firmware("mps2_an385")
    host = make_firmware("host")
    man = Manifest.load(out / "gen" / "acnframe.json")
    # the README documents the very command hil_sim.qemu runs (ports are examples there)
    readme = (REPO / "firmware" / "README.md").read_text()
    documented = " ".join(qemu_command("build/firmware/mps2_an385/accelnav_fw.elf", uart_ports=(5760, 5761)))
    assert documented in readme.replace("\\\n", " ")
    n = 3000
    code = 2048 + np.random.default_rng(4).integers(-80, 80, (n, 2))
    code[100, 1] = 0  # a rail
    stim = encode_stimulus(man, code=code)
    log = tmp_path / "qemu.acnlog"
    with Mps2Board(out / "accelnav_fw.elf") as board:
        tel, feed = board.open(0), board.open(1)
        rec = Recorder(tel, log, man, commands=(("info", {}),), status=Status(enabled=False))
        writer = threading.Thread(target=lambda: (time.sleep(0.2), feed.write(stim)), daemon=True)
        writer.start()
        res = rec.run(max_frames=n, duration=120)
        rec.close()
    assert res.reason == "frames", res
    assert res.info_ok is True
    d = decode_log(log)
    assert d.stats["lost"] == 0 and d.stats["crc_errors"] == 0 and d.stats["bad_frames"] == 0
    info = d.frames["info"][0]
    assert info["board"] == man.data["boards"]["mps2_an385"]
    ref = subprocess.run([host / "accelnav_fw"], input=stim, capture_output=True, timeout=60).stdout
    ref_frames, _ = decode_all(man, ref)
    np.testing.assert_array_equal(d.frames["sample"], ref_frames["sample"])  # bit-identical on the M3
    assert d.frames["sample"]["y.flags"][100] & 3 == 3
    print(f"\nqemu mps2-an385: {n} samples in {res.seconds:.1f} s ({n / res.seconds:.0f} samples/s)")


@needs_arm
@needs_qemu
def test_mps2_commands_in_qemu():
    out = make_firmware("mps2_an385")
    man = Manifest.load(out / "gen" / "acnframe.json")
    with Mps2Board(out / "accelnav_fw.elf") as board:
        deadline = time.monotonic() + 20
        tel, feed = board.open(0), board.open(1)
        tel.write(encode_command(man, "decimate", factor=10))
        time.sleep(0.2)
        feed.write(encode_stimulus(man, code=np.full((200, 2), 2048)))
        d = Decoder(man)
        got = {"sample": 0, "ack": 0}
        while got["sample"] < 20 and time.monotonic() < deadline + 20:
            b = d.feed(tel.read(4096))
            for k in got:
                got[k] += len(b[k])
    assert got == {"sample": 20, "ack": 1}
    assert d.stats.lost == 0


def test_readme_names_every_board():
    text = (REPO / "firmware" / "README.md").read_text()
    for word in ("BOARD=host", "BOARD=mps2_an385", "BOARD=stm32f103", "make flash", "st-flash", "openocd"):
        assert word in text
    assert os.path.isfile(REPO / "firmware" / "firmware.mk")
