"""``accelnav codegen MODEL --report --target PART`` (issue 26): does the filter fit the part?

The sizes are measured with the part's compiler and the firmware's flags; the part table is
firmware/parts.mk, which firmware.mk includes too, so the build's size check and this report read the
same numbers (checked here against the build's commands and the linker scripts). The compile-based
tests skip, with the reason, without the part's toolchain; under ACCELNAV_REQUIRE_AVR=1 (avr-gcc) or
ACCELNAV_REQUIRE_PIL=1 (arm-none-eabi-gcc, riscv64-unknown-elf-gcc) they fail instead.
"""

from __future__ import annotations

import os
import re
import subprocess

import pytest
from conftest import MODELS

from accelnav.cli import main
from accelnav.codegen import targets
from accelnav.codegen.generated import generate
from accelnav.model.load import load_model
from accelnav.resources import firmware_dir

DEFAULT = str(MODELS / "adxl250_default.toml")


def _need(part: str, env: str) -> targets.Part:
    p = targets.part(part)
    missing = targets.missing_tools(p)
    if missing:
        if os.environ.get(env) == "1":
            pytest.fail(f"{env}=1 but {missing}")
        pytest.skip(missing)
    return p


def _codegen(tmp_path, capsys, *extra):
    rc = main(["codegen", DEFAULT, "--out", str(tmp_path / "gen"), *extra])
    out, err = capsys.readouterr()
    return rc, out, err


def test_gain_schedule_on_atmega328p_is_refused_naming_the_covariance_form(tmp_path, capsys):
    p = _need("atmega328p", "ACCELNAV_REQUIRE_AVR")
    rc, _, err = _codegen(tmp_path, capsys, "--form", "gain_schedule", "--report", "--target", "atmega328p")
    assert rc == 2 and err.count("\n") == 1, err
    m = re.search(r"does not fit: needs (\d+) B flash of (\d+).*; the covariance form fits: (\d+) B flash", err)
    assert m, err
    assert int(m[2]) == p.flash == 32768
    assert int(m[1]) > p.flash >= int(m[3]) > 0
    assert not (tmp_path / "gen").exists(), "a filter that does not fit is not written"


def _fit(p: targets.Part, form: str) -> targets.Fit:
    """What ``accelnav codegen DEFAULT --form FORM --target PART`` measures, through the library."""
    model = load_model(DEFAULT)
    return targets.fit(p, model, form, "fixed", generate(model, form=form), "accelnav")


def test_covariance_form_fits_atmega328p():
    p = _need("atmega328p", "ACCELNAV_REQUIRE_AVR")
    fit = _fit(p, "covariance")
    s = fit.sized["covariance"]
    assert fit.fits("covariance") and 0 < s.flash <= p.flash and 0 < s.ram <= p.ram
    assert not fit.fits("gain_schedule") and fit.refusal() is None
    assert "the covariance form fits the atmega328p" in fit.lines()[-1]


def test_the_report_prints_the_librarys_fit(tmp_path, capsys):
    p = _need("uno", "ACCELNAV_REQUIRE_AVR")  # the alias names the same part
    rc, out, _ = _codegen(tmp_path, capsys, "--form", "covariance", "--report", "--target", "uno")
    assert rc == 0
    assert "\n".join(_fit(p, "covariance").lines()) in out


@pytest.mark.parametrize("name", ["sifive_e", "cortex-m3", "nrf51", "stm32f103"])
def test_the_32_bit_parts_hold_both_forms(name):
    p = _need(name, "ACCELNAV_REQUIRE_PIL")
    fit = _fit(p, "gain_schedule")
    assert set(fit.sized) == {"covariance", "gain_schedule"} and all(map(fit.fits, fit.sized))
    rows = {form: s.flash for form, s in fit.sized.items()}
    # the gain schedule carries its tables: more flash than the covariance form, on every part
    assert 0 < rows["covariance"] < rows["gain_schedule"] <= p.flash


def test_unknown_part_is_one_line_listing_the_known_ones(tmp_path, capsys):
    rc, _, err = _codegen(tmp_path, capsys, "--target", "pic16f84")
    assert rc == 2 and err.count("\n") == 1, err
    assert "unknown part 'pic16f84'" in err
    for key in ("atmega328p", "sifive_e/fe310", "mps2_an385/cortex-m3", "microbit/nrf51", "stm32f103"):
        assert key in err
    assert not (tmp_path / "gen").exists()


def test_a_missing_toolchain_is_said_and_gives_no_figure(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    rc, out, _ = _codegen(tmp_path, capsys, "--form", "gain_schedule", "--target", "atmega328p")
    assert rc == 0  # not measured, so not refused
    block = out[out.index("target atmega328p:") :].splitlines()
    assert block[1:] == ["  avr-gcc, avr-size, make not found: no figure for the atmega328p"], block


def test_the_build_compiles_and_checks_with_the_part_table(tmp_path):
    """firmware.mk's commands use each part's compiler and flags from the table, and the ATmega328P's
    size check its flash and RAM: the report and the build cannot disagree on a number."""
    gen = tmp_path / "gen"
    gen.mkdir()
    for name in ("accelnav.c", "accelnav.h", "acnframe.c", "acnframe.h"):
        (gen / name).write_text("")
    warn = " ".join(targets.warn_flags())
    for key, p in targets.parts().items():
        cmd = ["make", "-n", "-B", "--no-print-directory", "-f", str(firmware_dir() / "firmware.mk"), "firmware"]
        cmd += [f"BOARD={key}", f"FW_DIR={firmware_dir()}", f"FW_GEN={gen}", f"FW_OUT={tmp_path / key}", "FW_PREGEN=1"]
        text = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=tmp_path).stdout
        assert f"{p.cc} {warn} {' '.join(p.cflags)} " in text, (key, text[:400])
        if key == "atmega328p":
            assert f"flash > {p.flash} || ram + " in text and f"> {p.ram})" in text, text


@pytest.mark.parametrize(
    ("key", "script", "flash", "ram"),
    [("mps2_an385", "mps2_an385/mps2_an385.ld", "CODE", "DATA"), ("microbit", "microbit/nrf51822.ld", "CODE", "DATA"),
     ("sifive_e", "sifive_e/sifive_e.ld", "FLASH", "RAM"), ("stm32f103", "stm32f103/stm32f103c8.ld", "FLASH", "RAM")],
)  # fmt: skip
def test_the_linker_scripts_agree_with_the_part_table(key, script, flash, ram):
    text = (firmware_dir() / "boards" / script).read_text()

    def length(region: str) -> int:
        n, unit = re.search(rf"^\s*{region}\s*\(\w+\)\s*:.*LENGTH = (\d+)([KM]?)", text, re.M).groups()
        return int(n) * {"": 1, "K": 1024, "M": 1024 * 1024}[unit]

    p = targets.parts()[key]
    assert (length(flash), length(ram)) == (p.flash, p.ram)


Z_AXIS = '\n[[axes]]\nname = "z"\nc1 = 0.03\nc2 = -0.07\nT = 410.0\nzero_g_v = 2.497\n'


def fitted_model(tmp_path, n_axes: int):
    """The default model with 1, 2 or 3 axes, each with its own bias constants, as fit-bias writes them."""
    text = (MODELS / "adxl250_default.toml").read_text()
    head, _, rest = text.partition("[[axes]]")
    x, _, rest = rest.partition("[[axes]]")
    y, _, tail = rest.partition("\n[noise]")
    axes = ["[[axes]]" + x, "[[axes]]" + y, Z_AXIS.lstrip("\n") + "\n"][:n_axes]
    path = tmp_path / f"fitted{n_axes}.toml"
    path.write_text(head + "".join(axes) + "\n[noise]" + tail)
    return path


@pytest.mark.parametrize("n_axes", [1, 2, 3])
def test_the_report_states_the_size_of_the_linked_firmware(tmp_path, capsys, n_axes):
    """`--report --target atmega328p` states flash and RAM of the image as `make firmware BOARD=atmega328p`
    links it (within 2 %), not of the filter's object before the linker drops and adds code: the real link
    here is the firmware build the PIL runs use (hil_sim), whose own size check states what does not fit."""
    from accelnav.hil_sim.targets.firmware import FirmwareError, firmware_images

    p = _need("atmega328p", "ACCELNAV_REQUIRE_AVR")
    path = fitted_model(tmp_path, n_axes)
    rc = main(["codegen", str(path), "--out", str(tmp_path / "gen"), "--report", "--target", "atmega328p"])
    out, err = capsys.readouterr()
    row = re.search(r"^  covariance +(\d+) +(\d+)  (fits|does not fit)", out, re.M)
    refused = re.search(r"covariance form on the atmega328p does not fit: .*?(\d+) B flash of", err)
    refused_ram = re.search(r"does not fit: needs (?:\d+ B flash of \d+ and )?(\d+) B RAM", err)
    try:
        images = firmware_images("atmega328p", str(path))
    except FirmwareError as e:  # too big: the build's check says what it needs
        m = re.search(r"needs (\d+) B flash and (\d+) B RAM", str(e))
        real_flash, real_ram = int(m[1]), int(m[2])
    else:
        elf = tmp_path / "fw.elf"
        elf.write_bytes(images["accelnav_fw.elf"])
        size = subprocess.run(["avr-size", "-A", str(elf)], capture_output=True, text=True, check=True).stdout
        sec = {k: int(v) for k, v in re.findall(r"^(\.\w+)\s+(\d+)", size, re.M)}
        real_flash, real_ram = sec[".text"] + sec[".data"], sec[".data"] + sec.get(".bss", 0)
    fits = real_flash <= p.flash and real_ram + p.stack <= p.ram
    if fits:
        assert rc == 0 and row and row[3] == "fits", out + err
        assert abs(int(row[2]) - real_ram) <= 0.02 * real_ram, (row[2], real_ram)
        stated = int(row[1])
    else:
        assert rc == 2 and refused and err.count("\n") == 1, err
        stated = int(refused[1])
        if real_ram + p.stack > p.ram:  # refused for its RAM too: that figure is the image's as well
            assert refused_ram and abs(int(refused_ram[1]) - real_ram) <= 0.02 * real_ram, (err, real_ram)
    assert abs(stated - real_flash) <= 0.02 * real_flash, (stated, real_flash)


def test_a_filter_the_firmware_does_not_link_gets_its_object_size_and_no_verdict(tmp_path, capsys):
    """float32 (or another prefix) is not what the firmware links: the report sizes the filter's object, says
    that it is not the image, and neither passes nor refuses it."""
    _need("atmega328p", "ACCELNAV_REQUIRE_AVR")
    rc, out, err = _codegen(tmp_path, capsys, "--float32", "--target", "atmega328p")
    block = out[out.index("target atmega328p:") :].splitlines()
    assert rc == 0 and err == "" and len(block) == 2, out
    assert re.fullmatch(r"  the firmware links the fixed-point filter of prefix accelnav: covariance filter object "
                        r"alone \d+ B flash, \d+ B RAM, not linked: no verdict", block[1]), block  # fmt: skip
