"""The firmware, built the one way for each place it runs.

* :func:`generated`: the generated filter (``accelnav.*``) and frame code
  (``acnframe.*``) of a model, cached on disk by the model's text and the
  generator's source.
* :func:`build_firmware`: firmware/src, the host board and the generated C
  compiled with the strict flags (optionally with AddressSanitizer and
  UndefinedBehaviorSanitizer) into a cffi module: the firmware in-process
  (SIL), driven through :class:`HostFirmware`.
* :func:`firmware_images`: a board's image through the firmware's own
  Makefile fragment (the one ``make firmware BOARD=...`` uses), e.g. the
  mps2-an385 ELF that hil_sim.qemu runs (PIL); :func:`private_firmware`
  hands a runner verified copies, :func:`make_firmware` copies into a folder.

The firmware sources are package data (:func:`accelnav.resources.firmware_dir`);
what is built goes to the cache (:func:`accelnav.resources.cache_root`)
or a folder the caller names, never into the installed package.

An image is a sealed cache entry (:mod:`accelnav.cachefile`) like every other: built by ``make`` in a
private temporary folder (never from objects someone left in the cache), its files (ELF, hex, bin, the
host board's program, size.txt) packed into one entry named by the hash of everything it was built from
and sealed under the user's key. Every use verifies the seal and runs or loads a private copy of the
verified bytes (:func:`private_firmware`), never the cache file: an image replaced, edited or truncated
in the cache is rebuilt with one line on stderr, never run. Builders of one image take the entry's lock.
"""

from __future__ import annotations

import atexit
import hashlib
import json
import os
import re
import shutil
import struct
import subprocess
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache
from pathlib import Path

from accelnav.cachefile import cached, private_copy
from accelnav.fileio import TempFolder
from accelnav.native.cbuild import STRICT_WARN
from accelnav.resources import cache_root, firmware_dir, models_dir

FW = firmware_dir()
STRICT = [*STRICT_WARN, "-O1", "-g"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
DUTY_MODEL = models_dir() / "adxl202_duty.toml"
# the cross compiler of each board (firmware.mk's FW_CC) and its Debian packages; the boards not named are ARM
ARM_TOOLCHAIN = ("arm-none-eabi-gcc", "gcc-arm-none-eabi libnewlib-arm-none-eabi")
TOOLCHAINS = {"sifive_e": ("riscv64-unknown-elf-gcc", "gcc-riscv64-unknown-elf picolibc-riscv64-unknown-elf")}
IMAGE_LIMIT = 64 << 20  # the bytes of one board's image files together (an ARM ELF with -g: ~0.5 MB)
# what of a build folder is kept: the images the runners load and the size report, never objects
IMAGE_FILE = re.compile(r"(accelnav_fw(\.(elf|hex|bin))?|size\.txt)\Z")


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


def _compiler(board: str) -> str:
    """The board's compiler, found on PATH, else a one-line FirmwareError naming what to install."""
    if board == "atmega328p":
        cc, packages = "avr-gcc", "gcc-avr avr-libc"
        if shutil.which("avr-size") is None:
            raise FirmwareError(f"board {board}: avr-gcc not found (Debian: {packages})")
    elif board == "host":
        cc, packages = "cc", "gcc"
    else:
        cc, packages = TOOLCHAINS.get(board, ARM_TOOLCHAIN)
    path = shutil.which(cc)
    if path is None:
        raise FirmwareError(f"board {board}: {cc} not found (Debian: {packages})")
    if shutil.which("make") is None:
        raise FirmwareError(f"board {board}: make not found (Debian: make)")
    return path


@cache
def _sources_hash() -> bytes:
    """The firmware's files (sources, Makefile fragments, linker scripts): package data, fixed for a run.
    Not the fuzzers' growing corpus (``fuzz/``), which no image is built from."""
    h = hashlib.sha256()
    files = (q for q in FW.rglob("*") if q.is_file() and not {"__pycache__", "fuzz"} & set(q.relative_to(FW).parts))
    for p in sorted(files):
        h.update(str(p.relative_to(FW)).encode() + b"\0" + p.read_bytes() + b"\0")
    return h.digest()


def image_entry(board: str, model_path: str | Path | None = None) -> Path:
    """The cache entry of ``board``'s image for a model: named by the hash of the board, the firmware's
    files, the model's generated C and the compiler (its path, size and time: an upgrade rebuilds)."""
    cc = _compiler(board)
    st = os.stat(cc)
    h = hashlib.sha256(board.encode() + b"\0" + _sources_hash())
    h.update(f"{cc}\0{st.st_size}\0{st.st_mtime_ns}\0".encode())
    for name, text in sorted(generated(str(model_path) if model_path is not None else None).items()):
        h.update(name.encode() + b"\0" + text.encode() + b"\0")
    return cache_root() / "firmware" / f"{board}-{h.hexdigest()[:24]}.fw"


def _pack(files: dict[str, bytes]) -> bytes:
    head = json.dumps({name: len(data) for name, data in files.items()}).encode()
    return struct.pack("<I", len(head)) + head + b"".join(files.values())


def _unpack(blob: memoryview) -> dict[str, memoryview]:
    """The files of an image entry (views of its verified bytes); ValueError for one that is not whole."""
    if len(blob) < 4:
        raise ValueError("no image table")
    (n,) = struct.unpack_from("<I", blob)
    try:
        sizes = json.loads(bytes(blob[4 : 4 + n]))
    except ValueError:
        raise ValueError("a damaged image table") from None
    if not isinstance(sizes, dict) or not all(
        isinstance(k, str) and IMAGE_FILE.match(k) and type(v) is int and v >= 0 for k, v in sizes.items()
    ):
        raise ValueError("an image table of other files")
    at, files = 4 + n, {}
    for name, size in sizes.items():
        files[name] = blob[at : at + size]
        at += size
    if at != len(blob):
        raise ValueError(f"{len(blob)} bytes where the image table says {at}")
    return files


def _build(board: str, model_path: str | None) -> bytes:
    """``make`` in a private temporary folder, from nothing: the packed image files."""
    with TempFolder(f"fw-{board}") as out:
        gen = out / "gen"
        gen.mkdir()
        for name, text in generated(model_path).items():
            (gen / name).write_text(text)
        cmd = ["make", "--no-print-directory", "-f", str(FW / "firmware.mk"), "firmware", f"BOARD={board}",
               f"FW_DIR={FW}", f"FW_GEN={gen}", f"FW_OUT={out}", "FW_PREGEN=1"]  # fmt: skip
        try:
            done = subprocess.run(cmd, cwd=out, capture_output=True, text=True, timeout=600)
        except subprocess.TimeoutExpired:
            raise FirmwareError(f"board {board}: the firmware build did not finish within 600 s") from None
        if done.returncode != 0:
            # a model too big for the part: firmware.mk's size check says so in one line, which is the error
            fit = re.search(r"^BOARD=\S+: this model needs .*$", done.stderr, re.M)
            if fit:
                raise FirmwareError(fit[0])
            raise FirmwareError(f"{' '.join(cmd)} failed:\n{done.stdout[-2000:]}{done.stderr[-4000:]}")
        return _pack({p.name: p.read_bytes() for p in sorted(out.iterdir()) if IMAGE_FILE.match(p.name)})


def firmware_images(board: str, model_path: str | Path | None = None) -> dict[str, memoryview]:
    """``board``'s image files for a model (the embedded default if None), verified: from the sealed cache
    entry (:func:`image_entry`), else built (:func:`_build`) and sealed there. One that does not verify is
    rebuilt with one line on stderr; concurrent callers build it once (the entry's lock)."""
    model = None if model_path is None else str(model_path)
    entry = image_entry(board, model)
    return _unpack(memoryview(cached(entry, lambda: _build(board, model), limit=IMAGE_LIMIT, check=_unpack)))


def _write_images(folder: Path, images: dict[str, memoryview]) -> None:
    for name, data in images.items():
        private_copy(folder, name, data, 0o700 if name == "accelnav_fw" else 0o600)  # the host board runs


@contextmanager
def private_firmware(board: str, model_path: str | Path | None = None) -> Iterator[Path]:
    """A private folder (this user's, removed at the end) holding verified copies of ``board``'s image
    files: what an emulator loads, so a cache entry changed meanwhile cannot be what runs."""
    images = firmware_images(board, model_path)
    with TempFolder(f"fw-{board}") as folder:
        _write_images(folder, images)
        yield folder


def make_firmware(board: str, model_path: str | Path | None = None, out: Path | None = None) -> Path:
    """``board``'s image files (:func:`firmware_images`, verified) and the model's generated C (``gen/``)
    copied into a folder, returned.

    ``out``: a folder of the caller's (each file replaced whole); by default a private one of this process,
    removed when it exits. A runner that loads the image at once uses :func:`private_firmware` instead."""
    images = firmware_images(board, model_path)
    gen = {f"gen/{k}": v.encode() for k, v in generated(None if model_path is None else str(model_path)).items()}
    if out is None:
        folder = TempFolder(f"fw-{board}")
        atexit.register(folder.close)
        (folder.path / "gen").mkdir()
        _write_images(folder.path, {**images, **gen})
        return folder.path
    out = Path(out)
    (out / "gen").mkdir(parents=True, exist_ok=True)
    with TempFolder(f"fw-{board}", out) as tmp:  # beside the targets: each rename is atomic
        (tmp / "gen").mkdir()
        _write_images(tmp, {**images, **gen})
        for name in (*images, *gen):
            os.replace(tmp / name, out / name)
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
