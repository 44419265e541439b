"""Build the firmware's C (host board) into a cffi module, for the round-trip and fuzz tests.

:func:`generated` runs the generators once per (model, form) and caches the
text; :func:`build_firmware` compiles firmware/src/*.c, the host board and the
generated filter and frame code with the strict flags (optionally with
AddressSanitizer and UndefinedBehaviorSanitizer) and returns the imported
module. Run as a script, it is the sanitized command-parser fuzzer (see
tests/test_telemetry_fuzz.py, which starts it with libasan preloaded).
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import subprocess
import sys
from functools import cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FW = REPO / "firmware"
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-g"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
DUTY_MODEL = REPO / "models" / "adxl202_duty.toml"


@cache
def generated(model_path: str | None = None) -> dict[str, str]:
    """accelnav.{h,c,json} and acnframe.{h,c,json} of a model (the embedded default if None)."""
    from codegen.emit_c import emit
    from codegen.frames import emit_frames
    from codegen.model import load_model

    model = load_model(model_path)
    # the generator takes seconds: keep its output on disk, keyed by the model and the generator's source
    key = hashlib.sha256(model.text.encode())
    for p in sorted((REPO / "codegen").glob("*.py")):
        key.update(p.read_bytes())
    cache = _cache_root() / f"gen-{key.hexdigest()[:20]}.json"
    if cache.exists():
        return json.loads(cache.read_text())
    files = emit(model)
    files.update(emit_frames(model, json.loads(files["accelnav.json"])))
    cache.parent.mkdir(parents=True, exist_ok=True)
    tmp = cache.with_suffix(f".{os.getpid()}.tmp")
    tmp.write_text(json.dumps(files))
    os.replace(tmp, cache)
    return files


def _cache_root() -> Path:
    return Path(os.environ.get("ACCELNAV_BUILD_DIR") or REPO / "build" / "cffi")


def manifest(model_path: str | None = None):
    from host.telemetry import Manifest

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
                 uint16_t overflow; acnf_axis_t axis[{n}]; }} acnf_sample_t;
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
void app_init(void);
void app_sample(const acnf_stimulus_t *in);
void app_rx(unsigned ch, const uint8_t *p, size_t n);
"""


def build_firmware(model_path: str | None = None, *, sanitize: bool = False, workdir: Path | None = None):
    """The host-board firmware as a cffi module (``.ffi``, ``.lib``), cached by the hash of its sources."""
    import cffi

    files = generated(model_path)
    sources = {p.name: p.read_text() for p in sorted((FW / "src").glob("*.[ch]"))}
    sources.update({p.name: p.read_text() for p in sorted((FW / "boards" / "host").glob("*.[ch]"))})
    sources["acn_board.h"] = (FW / "boards" / "acn_board.h").read_text()
    sources.update({k: v for k, v in files.items() if not k.endswith(".json")})
    sources.pop("main.c")
    flags = STRICT + (SANITIZE if sanitize else [])
    key = "\0".join([*flags, *(f"{k}\0{v}" for k, v in sorted(sources.items())), sys.version, cffi.__version__])
    modname = f"_acn_fw_{hashlib.sha256(key.encode()).hexdigest()[:16]}"
    if modname in sys.modules:
        return sys.modules[modname]
    root = Path(workdir or _cache_root()) / modname
    root.mkdir(parents=True, exist_ok=True)
    so = next(root.glob(f"{modname}*.so"), None)
    if so is None:
        for name, text in sources.items():
            (root / name).write_text(text)
        objs = []
        cc = os.environ.get("CC", "gcc")
        for name in sorted(n for n in sources if n.endswith(".c")):
            obj = root / (name[:-2] + ".o")
            cmd = [cc, *flags, "-fPIC", f"-I{root}", "-c", str(root / name), "-o", str(obj)]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode:
                raise RuntimeError(f"{' '.join(cmd)}:\n{done.stderr}")
            objs.append(str(obj))
        ffi = cffi.FFI()
        ffi.cdef(_cdef(files))
        ffi.set_source(
            modname,
            '#include "acnframe.h"\n#include "link.h"\n#include "cobs.h"\n#include "crc32.h"\n'
            '#include "acn_board.h"\n#include "board_host.h"\n',
            include_dirs=[str(root)],
            extra_objects=objs,
            extra_link_args=SANITIZE if sanitize else [],
        )
        so = Path(ffi.compile(tmpdir=str(root), verbose=False))
    spec = importlib.util.spec_from_file_location(modname, so)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    sys.modules[modname] = mod
    return mod


class HostFirmware:
    """The firmware in-process: feed bytes, collect telemetry."""

    def __init__(self, mod):
        self.ffi, self.lib = mod.ffi, mod.lib
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


# --------------------------------------------------------------------------
# The sanitized fuzzer (run as a script with libasan preloaded)


def fuzz(examples: int, random_inputs: int, seed: int = 5) -> dict:
    """Drive the command/stimulus parser with hypothesis-built and plain random inputs; returns counts."""
    import numpy as np
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    from host.telemetry import encode_command, encode_stimulus, frame

    mod = build_firmware(sanitize=True)
    fw = HostFirmware(mod)
    man = manifest()
    ffi, lib = mod.ffi, mod.lib
    counts = {"hypothesis_inputs": 0, "random_inputs": 0}
    cmd_out = ffi.new("acnf_command_t *")
    n_axes = len(man.axes)

    valid = st.one_of(
        st.sampled_from(["start", "stop", "reset", "info", "zupt_begin", "zupt_end"]).map(
            lambda c: encode_command(man, c)
        ),
        st.integers(0, 65535).map(lambda f: encode_command(man, "decimate", factor=f)),
        st.lists(st.integers(0, 4095), min_size=n_axes, max_size=n_axes).map(
            lambda c: encode_stimulus(man, code=np.array([c]))
        ),
        st.binary(min_size=0, max_size=40).map(frame),  # well framed, arbitrary payload
    )
    chunk = st.one_of(valid, st.binary(max_size=64), st.just(b"\0"), st.binary(min_size=200, max_size=600))

    @settings(
        max_examples=examples, derandomize=True, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(st.lists(chunk, max_size=24), st.integers(0, 1), st.binary(max_size=48))
    def one(chunks, ch, payload):
        data = b"".join(chunks)
        fw.rx(data, ch)
        lib.acnf_parse_command(payload, len(payload), cmd_out)
        fw.take()
        counts["hypothesis_inputs"] += 1

    one()
    rng = np.random.default_rng(seed)
    for _ in range(random_inputs):
        n = int(rng.integers(0, 256))
        data = rng.integers(0, 256, n, dtype=np.uint8)
        data[rng.random(n) < 0.05] = 0  # delimiters now and then
        b = data.tobytes()
        fw.rx(b, int(rng.integers(0, 2)))
        lib.acnf_parse_command(b, len(b), cmd_out)
        counts["random_inputs"] += 1
        if counts["random_inputs"] % 64 == 0:
            fw.take()
    return counts


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    result = fuzz(int(sys.argv[1]), int(sys.argv[2]))
    print(json.dumps(result))
