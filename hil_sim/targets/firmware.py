"""The firmware, built the one way for each place it runs.

* :func:`generated`: the generated filter (``accelnav.*``) and frame code
  (``acnframe.*``) of a model, cached on disk by the model's text and the
  generator's source.
* :func:`build_firmware`: firmware/src, the host board and the generated C
  compiled with the strict flags (optionally with AddressSanitizer and
  UndefinedBehaviorSanitizer) into a cffi module: the firmware in-process
  (SIL), driven through :class:`HostFirmware`.
* :func:`make_firmware`: an image for a board through the firmware's own
  Makefile fragment (the one ``make firmware BOARD=...`` uses), e.g. the
  mps2-an385 ELF that hil_sim.qemu runs (PIL).

The firmware sources are package data (:func:`accelnav.resources.firmware_dir`);
what is built goes to the cache (:func:`accelnav.resources.cache_root`)
or a folder the caller names, never into the installed package.

Unlike the other cache entries (:mod:`accelnav.cachefile`), a board's image
folder is not sealed: ``make`` builds in it incrementally and trusts the
objects it finds there, so whoever can write the cache folder can change the
image the emulator runs. Builds of one folder take a lock, one at a time; the
user guide ("The cache folder") says to keep PIL's cache private.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from functools import cache
from pathlib import Path

from accelnav.cachefile import entry_lock
from accelnav.native.cbuild import STRICT_WARN
from accelnav.resources import cache_root, firmware_dir, models_dir

FW = firmware_dir()
STRICT = [*STRICT_WARN, "-O1", "-g"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
DUTY_MODEL = models_dir() / "adxl202_duty.toml"
# the cross compiler of each board (firmware.mk's FW_CC) and its Debian packages; the boards not named are ARM
ARM_TOOLCHAIN = ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi")
TOOLCHAINS = {"sifive_e": ("riscv64-unknown-elf-gcc", "gcc-riscv64-unknown-elf picolibc-riscv64-unknown-elf")}


@cache
def generated(model_path: str | None = None) -> dict[str, str]:
    """accelnav.{h,c,json} and acnframe.{h,c,json} of a model (the embedded default if None)."""
    from accelnav.codegen.generated import generated_files
    from accelnav.model.load import load_model

    return generated_files(load_model(model_path))


def manifest(model_path: str | None = None):
    from accelnav.link.manifest import Manifest

    return Manifest(json.loads(generated(model_path)["acnframe.json"]))


def _cdef(files: dict[str, str]) -> str:
    man = json.loads(files["acnframe.json"])
    n = len(man["axes"])
    duty = man["input"] == "duty_cycle"
    raw = "uint32_t t1; uint32_t t2;" if duty else "uint16_t code;"
    stim = f"uint32_t t1[{n}]; uint32_t t2[{n}];" if duty else f"uint16_t code[{n}];"
    return f"""
typedef struct {{ uint8_t flags; {raw} int64_t r; int64_t u; int32_t a; int64_t e; }} acnf_axis_t;
typedef struct {{ uint16_t seq; uint32_t index; uint16_t flags; uint16_t tx_drop; uint16_t skipped;
                 uint16_t overflow; uint16_t missed; uint16_t rx_lost; acnf_axis_t axis[{n}]; }} acnf_sample_t;
typedef struct {{ uint8_t type; uint16_t factor; }} acnf_command_t;
typedef struct {{ uint8_t flags; {stim} }} acnf_stimulus_t;
size_t acnf_pack_sample(const acnf_sample_t *s, uint8_t *p);
bool acnf_parse_command(const uint8_t *p, size_t n, acnf_command_t *c);
bool acnf_parse_stimulus(const uint8_t *p, size_t n, acnf_stimulus_t *t);
size_t link_frame(const uint8_t *payload, size_t n, uint8_t *out);
size_t cobs_encode(const uint8_t *in, size_t n, uint8_t *out);
size_t cobs_decode(const uint8_t *in, size_t n, uint8_t *out);
uint32_t crc32_update(uint32_t crc, const uint8_t *p, size_t n);
void board_init(void);
size_t board_host_take(uint8_t *out, size_t max);
void board_host_set_tx_limit(size_t limit);
void board_host_set_boot_id(uint16_t id);
void app_init(void);
void app_sample(const acnf_stimulus_t *in);
void app_missed(uint32_t n);
void app_rx(unsigned ch, const uint8_t *p, size_t n);
"""


def build_firmware(model_path: str | None = None, *, sanitize: bool = False, workdir: Path | None = None):
    """The host-board firmware as a cffi module (``.ffi``, ``.lib``), built once per source text."""
    from accelnav.native.cbuild import build_module

    files = generated(model_path)
    sources = {p.name: p.read_text() for p in sorted((FW / "src").glob("*.[ch]"))}
    sources.update({p.name: p.read_text() for p in sorted((FW / "boards" / "host").glob("*.[ch]"))})
    sources["acn_board.h"] = (FW / "boards" / "acn_board.h").read_text()
    sources.update({k: v for k, v in files.items() if not k.endswith(".json")})
    sources.pop("main.c")
    preamble = "".join(
        f'#include "{h}"\n' for h in ("acnframe.h", "link.h", "cobs.h", "crc32.h", "acn_board.h", "board_host.h")
    )
    return build_module(
        "acn_fw_asan" if sanitize else "acn_fw",
        _cdef(files),
        sources,
        main=sorted(n for n in sources if n.endswith(".c")),
        preamble=preamble,
        extra_compile_args=STRICT + (SANITIZE if sanitize else []),
        extra_link_args=SANITIZE if sanitize else [],
        workdir=workdir,
    )


def make_firmware(board: str, model_path: str | Path | None = None, out: Path | None = None) -> Path:
    """Build ``board``'s image with the firmware's Makefile fragment and return its output folder.

    The generated C of the model is written to ``OUT/gen`` first; ``out``
    defaults to a folder in the cache named by the board and the model's
    hash, so images of different models never overwrite each other. The build
    holds a lock on the folder (``OUT.lock``): a second process building the same
    image waits, then finds it made, instead of relinking it under the first.
    """
    from accelnav.model.load import load_model

    model = load_model(model_path)
    if out is None:
        out = cache_root() / "firmware" / f"{board}-{model.sha256[:16]}"
    out = Path(out).resolve()
    if board == "atmega328p":
        if shutil.which("avr-gcc") is None or shutil.which("avr-size") is None:
            raise FirmwareError(f"board {board}: avr-gcc not found (Debian: gcc-avr avr-libc)")
    elif board != "host":
        cc, packages = TOOLCHAINS.get(board, ARM_TOOLCHAIN)
        if shutil.which(cc) is None:
            raise FirmwareError(f"board {board}: {cc} not found (Debian: {packages})")
    if shutil.which("make") is None:
        raise FirmwareError(f"board {board}: make not found (Debian: make)")
    # one build at a time per folder: two makes in one folder delete and relink each other's image
    with entry_lock(out):
        gen = out / "gen"
        gen.mkdir(parents=True, exist_ok=True)
        for name, text in generated(model_path).items():
            path = gen / name
            if not path.exists() or path.read_text() != text:  # unchanged files keep their time: no rebuild
                path.write_text(text)
        cmd = [
            "make",
            "--no-print-directory",
            "-f",
            str(FW / "firmware.mk"),
            "firmware",
            f"BOARD={board}",
            f"FW_DIR={FW}",
            f"FW_GEN={gen}",
            f"FW_OUT={out}",
            "FW_PREGEN=1",
        ]
        done = subprocess.run(cmd, cwd=out, capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        # a model too big for the part: firmware.mk's size check says so in one line, which is the error
        fit = re.search(r"^BOARD=\S+: this model needs .*$", done.stderr, re.M)
        if fit:
            raise FirmwareError(fit[0])
        raise FirmwareError(f"{' '.join(cmd)} failed:\n{done.stdout[-2000:]}{done.stderr[-4000:]}")
    return out


class FirmwareError(RuntimeError):
    """A firmware build that could not be done (missing toolchain, compile error)."""


class HostFirmware:
    """The firmware in-process: feed bytes, collect telemetry."""

    def __init__(self, mod, boot_id: int = 1):
        """``boot_id``: what the board says at power-on (1 on every board without a retained counter)."""
        self.ffi, self.lib = mod.ffi, mod.lib
        self.lib.board_host_set_boot_id(boot_id)
        self.lib.board_init()
        self.lib.board_host_set_tx_limit(1 << 16)
        self.lib.app_init()
        self._buf = self.ffi.new("uint8_t[]", 1 << 16)
        self._out = bytearray()

    def rx(self, data: bytes, ch: int = 0, step: int = 4096) -> None:
        """Feed bytes in pieces of ``step``, moving the telemetry out between pieces (a fast link)."""
        for a in range(0, len(data), step):
            part = data[a : a + step]
            self.lib.app_rx(ch, part, len(part))
            self._drain()

    def _drain(self) -> None:
        while True:
            n = self.lib.board_host_take(self._buf, len(self._buf))
            if n == 0:
                return
            self._out += self.ffi.buffer(self._buf, n)[:]

    def take(self) -> bytes:
        """All telemetry since the last take()."""
        self._drain()
        out, self._out = bytes(self._out), bytearray()
        return out
