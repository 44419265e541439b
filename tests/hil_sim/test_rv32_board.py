"""The RV32IMAC board (QEMU sifive_e, a SiFive FE310 without FPU): its image is what the part runs
(32-bit RISC-V, compressed instructions, soft-float ABI, no F or D extension, entry where the mask
ROM jumps) and fits the FE310's 16 KiB DTIM for both shipped models in both forms; the README
documents the command line hil_sim.qemu runs; a missing RISC-V tool is one line naming its Debian
package. Its PIL runs (bit for bit against SIL) are in tests/hil_sim/test_hil.py's matrix.

Skipped, with the reason, without riscv64-unknown-elf-gcc; a failure under ACCELNAV_REQUIRE_PIL=1 (CI).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest
from conftest import MODELS, REPO

from accelnav.hil_sim.targets import firmware, qemu
from accelnav.model.load import load_model

DTIM = 16 * 1024  # the FE310's data RAM; sifive_e.ld also keeps 2 KiB of it for the stack
ENTRY = 0x20400000  # where QEMU's sifive_e mask ROM jumps (the HiFive1's program flash)


def _require_riscv():
    if shutil.which("riscv64-unknown-elf-gcc") is None:
        reason = "needs riscv64-unknown-elf-gcc (Debian: gcc-riscv64-unknown-elf picolibc-riscv64-unknown-elf)"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but the sifive_e board {reason}")
        pytest.skip(reason)


def _model(tmp_path, name: str, form: str) -> Path:
    path = MODELS / f"{name}.toml"
    text = path.read_text()
    shipped = re.search(r'^form = "(\w+)"', text, re.M)
    if shipped.group(1) == form:
        return path
    out = tmp_path / f"{name}_{form}.toml"
    out.write_text(text[: shipped.start()] + f'form = "{form}"' + text[shipped.end() :])
    return out


@pytest.mark.parametrize("form", ["covariance", "gain_schedule"])
@pytest.mark.parametrize("name", ["adxl250_default", "adxl202_duty"])
def test_sifive_e_image_is_rv32imac_and_fits(tmp_path, name, form):
    _require_riscv()
    model = load_model(_model(tmp_path, name, form))
    assert model.filter.form == form
    out = firmware.make_firmware("sifive_e", model.source)
    text, data, bss = (int(x) for x in (out / "size.txt").read_text().splitlines()[1].split()[:3])
    print(f"\nsifive_e {name} {form}: text {text}, data {data}, bss {bss}")
    assert data + bss + 2048 <= DTIM
    elf = out / "accelnav_fw.elf"
    hdr = subprocess.run(["riscv64-unknown-elf-readelf", "-h", "-A", elf], capture_output=True, text=True).stdout
    assert re.search(r"Class:\s+ELF32", hdr) and re.search(r"Machine:\s+RISC-V", hdr), hdr
    assert re.search(r"Flags:\s+0x1, RVC, soft-float ABI", hdr), hdr  # no FPU registers in the ABI
    arch = re.search(r'Tag_RISCV_arch: "(\w+)"', hdr).group(1)
    exts = {m.group(1) for m in re.finditer(r"_?([a-z])\d+p\d+", arch)}
    assert {"i", "m", "a", "c"} <= exts and not exts & {"f", "d"}, arch
    assert int(re.search(r"Entry point address:\s+(0x[0-9a-f]+)", hdr).group(1), 16) == ENTRY


def test_readme_documents_the_sifive_e_command_line():
    readme = (REPO / "firmware" / "README.md").read_text()
    m = qemu.machine_for("sifive_e")
    cmd = qemu.qemu_command(
        "build/firmware/sifive_e/accelnav_fw.elf", uart_ports=(5760,), machine=m.machine, qemu=m.qemu
    )
    assert " ".join(cmd) in readme
    row = next(line for line in readme.splitlines() if line.startswith("| `sifive_e`"))
    assert "run in CI" in row and "BOARD=sifive_e" in readme


def test_missing_riscv_tools_are_one_line_errors(monkeypatch, tmp_path):
    monkeypatch.setattr(shutil, "which", lambda name: None)  # no tool installed at all
    elf = tmp_path / "fw.elf"
    elf.write_bytes(b"\x7fELF")
    with pytest.raises(qemu.QemuError, match=r"^qemu-system-riscv32 not found: install Debian's qemu-system-misc"):
        qemu.run_feed(elf, "sifive_e", b"")
    with pytest.raises(firmware.FirmwareError, match="riscv64-unknown-elf-gcc not found.*picolibc-riscv64-unknown-elf"):
        firmware.make_firmware("sifive_e", None, tmp_path / "out")


def test_bench_counts_rv32_instructions_beside_the_m3(tmp_path):
    """hil_sim.targets.icount_sample (what bench/speed/bench_rv32_icount.py prints): both cores count a known
    loop right, compute the same final states (checkpoint images) for both forms, and RV32IMAC, without the
    M3's 32x32->64 multiply-accumulate, needs more instructions per 2-axis sample than the M3 for each form."""
    _require_riscv()
    if shutil.which("arm-none-eabi-gcc") is None or shutil.which("qemu-system-arm") is None:
        reason = "the M3 side needs arm-none-eabi-gcc and qemu-system-arm (Debian: gcc-arm-none-eabi qemu-system-arm)"
        if os.environ.get("ACCELNAV_REQUIRE_PIL") == "1":
            pytest.fail(f"ACCELNAV_REQUIRE_PIL=1 but {reason}")
        pytest.skip(reason)
    from accelnav.hil_sim.sim.sensor import simulate
    from accelnav.hil_sim.targets.icount_sample import driver, run_core

    model = load_model()
    main_c = driver(model, simulate(model, "vehicle", 300 / model.rate_hz, seed=1).code[:300])
    vals = {core: run_core(core, model, main_c, tmp_path / core)[0] for core in ("M3", "RV32")}
    m3, rv32 = vals["M3"], vals["RV32"]
    assert m3["calib_2M"] == 2_000_000
    assert 2_000_000 <= rv32["calib_2M"] <= 2_000_010  # the loop and the few instructions of its call
    assert (m3["hash_cov"], m3["hash_gs"]) == (rv32["hash_cov"], rv32["hash_gs"]), "final states differ"
    assert m3["overflow"] == 0 and rv32["overflow"] == 0
    for tag in ("cov", "gs"):
        per_m3, per_rv32 = m3[tag] / m3["n"], rv32[tag] / rv32["n"]
        assert per_rv32 > per_m3 > 20, (tag, per_m3, per_rv32)


def test_a_trap_ends_the_run_with_fault_not_a_hang(tmp_path):
    """startup.c points mtvec at board_fault: an illegal instruction says 'fault' and exits 1 at once."""
    _require_riscv()
    if shutil.which("qemu-system-riscv32") is None:
        pytest.skip("needs qemu-system-riscv32 (Debian: qemu-system-misc)")
    boards = REPO / "firmware" / "boards"
    (tmp_path / "main.c").write_text(
        '#include "board.h"\nint main(void)\n{\n    board_puts("before\\n");\n'
        '    __asm__ volatile(".word 0"); /* an illegal instruction */\n    board_puts("after\\n");\n    return 0;\n}\n'
    )
    elf = tmp_path / "fault.elf"
    cmd = ["riscv64-unknown-elf-gcc", "-march=rv32imac", "-mabi=ilp32", "-O2", "--specs=picolibc.specs"]
    cmd += [
        "-nostartfiles",
        "-I",
        str(boards / "sifive_e"),
        "-I",
        str(boards),
        "-T",
        str(boards / "sifive_e" / "sifive_e.ld"),
    ]
    cmd += [
        str(tmp_path / "main.c"),
        str(boards / "sifive_e" / "startup.c"),
        str(boards / "semihost_rt.c"),
        "-o",
        str(elf),
    ]
    subprocess.run(cmd, check=True)
    m = qemu.machine_for("sifive_e")
    with pytest.raises(qemu.QemuError, match="exited with status 1"):
        qemu.run_to_exit(elf, icount=False, timeout=20, machine=m.machine, qemu=m.qemu)
    cmd = qemu.qemu_command(elf, machine=m.machine, qemu=m.qemu)
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=20)
    assert done.returncode == 1 and done.stdout + done.stderr == "before\nfault\n"
