"""The firmware builds for every board with -Werror, the host board runs as a program, and the
mps2_an385 image runs in qemu-system-arm: telemetry on UART0, stimulus on UART1, both over TCP
(pyserial socket://), bit-identical to the host board; the microbit (Cortex-M0) and
stm32vldiscovery (the STM32 port on QEMU's STM32F100) images answer commands there too (their
bit-for-bit runs are in test_hil.py). The C is clang-format clean.

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
from conftest import REPO

from accelnav.hil_sim.targets.firmware import DUTY_MODEL
from accelnav.hil_sim.targets.firmware import make_firmware as build_image
from accelnav.hil_sim.targets.hil import wait_ready
from accelnav.hil_sim.targets.qemu import MACHINES, Mps2Board, QemuBoard, qemu_command
from accelnav.link.codec import encode_command, encode_stimulus
from accelnav.link.decoder import Decoder, decode_all, replay_for
from accelnav.link.manifest import Manifest
from accelnav.link.recorder import Recorder, Status, decode_log
from accelnav.model.load import load_model

STM32_FLASH, STM32_RAM = 64 * 1024, 20 * 1024
# flash, RAM of the emulated parts: nRF51822 (microbit), STM32F100RB (stm32vldiscovery)
EMULATED_MEMORY = {"microbit": (256 * 1024, 16 * 1024), "stm32vldiscovery": (128 * 1024, 8 * 1024)}

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
    stdin = encode_command(man, "info") + encode_stimulus(man, code=code) + encode_command(man, "flush")
    done = subprocess.run([out / "accelnav_fw"], input=stdin, capture_output=True, timeout=60)
    assert done.returncode == 0
    frames, stats = decode_all(man, done.stdout, replay_for(man, load_model()))
    assert len(frames["sample"]) == 300 and len(frames["info"]) == 1 and stats.bad_frames == 0
    assert stats.mismatches == 0 and stats.checkpoints == 4
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
@pytest.mark.parametrize("board", sorted(EMULATED_MEMORY))
@pytest.mark.parametrize("model", [None, DUTY_MODEL], ids=["adxl250", "adxl202"])
def test_emulated_boards_build_and_fit(board, model):
    out = make_firmware(board, model)
    s = sizes(out)
    flash, ram = EMULATED_MEMORY[board]
    print(f"\n{board} ({'default' if model is None else model.stem}): {s}")
    assert s["text"] + s["data"] <= flash
    assert s["data"] + s["bss"] + 2048 <= ram  # the linker scripts keep 2 KiB for the stack
    hdr = subprocess.run(["arm-none-eabi-readelf", "-h", "-A", out / "accelnav_fw.elf"], capture_output=True, text=True)
    # the M0 image is ARMv6-M code (no 32x32->64 multiply); the STM32 one the F103's ARMv7-M
    assert re.search(r"Tag_CPU_arch: v6S-M" if board == "microbit" else r"Tag_CPU_arch: v7", hdr.stdout), hdr.stdout
    if board == "stm32vldiscovery":  # the STM32F103 layout: vector table at the start of flash
        assert re.search(r"Entry point address:\s+0x80", hdr.stdout)


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
        *sorted((REPO / "firmware" / "boards").glob("*.[ch]")),
        *sorted((REPO / "firmware" / "boards" / "host").glob("*.[ch]")),
        REPO / "firmware" / "boards" / "mps2_an385" / "board_mps2.c",
        *sorted((REPO / "firmware" / "boards" / "microbit").glob("*.[ch]")),
        *sorted((REPO / "firmware" / "boards" / "stm32f103").glob("*.[ch]")),
        *sorted((REPO / "firmware" / "boards" / "sifive_e").glob("*.[ch]")),
    ]
    done = subprocess.run(["clang-format", "--dry-run", "-Werror", *ours], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-3000:]


def test_firmware_refuses_a_generated_filter_of_another_runtime_api(tmp_path):
    """filter_adapter.h is written against the generated API (RUNTIME_API 2: the checkpoint image,
    accelnav_<axis>_save): an accelnav.h of another API stops the build with one line saying to
    regenerate, rather than at the link."""
    from accelnav.codegen.package import RUNTIME_API
    from accelnav.hil_sim.targets.firmware import generated

    cc = shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler")
    files = generated()
    (tmp_path / "main.c").write_text('#include "filter_adapter.h"\nint main(void) { return 0; }\n')
    for api in (RUNTIME_API, RUNTIME_API - 1):
        for name in ("accelnav.h", "acnframe.h"):
            text = files[name]
            if name == "accelnav.h":
                text = text.replace(
                    f"#define ACCELNAV_RUNTIME_API {RUNTIME_API}\n", f"#define ACCELNAV_RUNTIME_API {api}\n"
                )
            (tmp_path / name).write_text(text)
        done = subprocess.run(
            [cc, "-std=c99", "-fsyntax-only", "-I", str(tmp_path), "-I", str(REPO / "firmware" / "src"), "main.c"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
        )
        if api == RUNTIME_API:
            assert done.returncode == 0, done.stderr[-2000:]
        else:
            assert done.returncode != 0 and "another runtime API" in done.stderr


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
    fed = " ".join(qemu_command("/abs/path/accelnav_fw.elf", feed=("stim.bin", "tel.bin")))
    assert fed in readme  # the file feed PIL runs (hil_sim.qemu.run_feed)
    n = 3000
    code = 2048 + np.random.default_rng(4).integers(-80, 80, (n, 2))
    code[100, 1] = 0  # a rail
    stim = encode_stimulus(man, code=code) + encode_command(man, "flush")
    log = tmp_path / "qemu.acnlog"
    model_text = load_model().text  # the compact frames' states: the host replays the firmware's C
    with Mps2Board(out / "accelnav_fw.elf") as board:
        tel, feed = board.open(0), board.open(1)
        rec = Recorder(tel, log, man, commands=(("info", {}),), model_text=model_text, status=Status(enabled=False))
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
    ref_frames, _ = decode_all(man, ref, replay_for(man, load_model()))
    np.testing.assert_array_equal(d.frames["sample"], ref_frames["sample"])  # bit-identical on the M3
    for name in ("block", "checkpoint"):  # what the M3 computed: its checkpoints are the host board's
        assert d.frames[name].tobytes() == ref_frames[name].tobytes()
    assert d.stats["mismatches"] == 0 and d.stats["checkpoints"] == 2 * (n // man.data["checkpoint_samples"] + 1)
    assert d.frames["sample"]["y.flags"][100] & 3 == 3
    print(f"\nqemu mps2-an385: {n} samples in {res.seconds:.1f} s ({n / res.seconds:.0f} samples/s)")


@needs_arm
@needs_qemu
@pytest.mark.parametrize("board_name", sorted(MACHINES))
def test_commands_in_qemu(board_name):
    out = make_firmware(board_name)
    man = Manifest.load(out / "gen" / "acnframe.json")
    with QemuBoard(out / "accelnav_fw.elf", board_name) as board:
        tel, feed = board.open(board.machine.telemetry), board.open(board.machine.stimulus)
        # QEMU's STM32 USART drops what comes before the firmware enables it: a command written right
        # after connecting was lost when the emulator started late (seen on a loaded machine)
        wait_ready(tel, man, board_name)
        deadline = time.monotonic() + 20
        tel.write(encode_command(man, "decimate", factor=10) + encode_command(man, "info"))
        time.sleep(0.2)
        feed.write(encode_stimulus(man, code=np.full((200, 2), 2048)))
        d = Decoder(man)
        got = {"sample": 0, "ack": 0, "info": 0}
        infos = []
        while got["sample"] < 20 and time.monotonic() < deadline + 20:
            b = d.feed(tel.read(4096))
            infos += list(b["info"])
            for k in got:
                got[k] += len(b[k])
    assert got == {"sample": 20, "ack": 2, "info": 1}
    assert d.stats.lost == 0
    assert infos[0]["board"] == man.data["boards"][board_name]  # the image says which board it is


def test_readme_names_every_board():
    text = (REPO / "firmware" / "README.md").read_text()
    for word in (
        "BOARD=host",
        "BOARD=mps2_an385",
        "BOARD=microbit",
        "BOARD=stm32f103",
        "BOARD=stm32vldiscovery",
        "BOARD=netduino2",
        "make flash",
        "st-flash",
        "openocd",
    ):
        assert word in text
    assert os.path.isfile(REPO / "firmware" / "firmware.mk")
    # the board table says, for every board, whether CI runs it or only builds it
    for board in ("host", "mps2_an385", "microbit", "stm32f103", "stm32vldiscovery", "netduino2"):
        row = next((line for line in text.splitlines() if line.startswith(f"| `{board}`")), None)
        assert row is not None, f"no row for {board} in the README's board table"
        assert ("run in CI" in row) != ("build only" in row), row


def test_unknown_board_lists_the_accepted_ones():
    done = subprocess.run(
        ["make", "-f", REPO / "firmware" / "firmware.mk", "firmware", "BOARD=nrf52"], capture_output=True, text=True
    )
    assert done.returncode != 0
    assert "accepted: host, mps2_an385, microbit, stm32f103, stm32vldiscovery" in done.stderr
