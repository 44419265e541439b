"""Build generated C into a Python module with cffi (API mode).

``build(files, workdir)`` compiles the generated ``PREFIX.c`` with the
declarations cut from ``PREFIX.h`` (so the C and Python cannot drift) and
returns the imported module (``.ffi``, ``.lib``). Modules are keyed by the
hash of the generated text and cached in ``workdir``: the same model builds
once. ``sanitize=True`` adds -fsanitize=undefined,address (the test process
must then preload libasan; see tests/test_codegen_sanitize.py).

:class:`AxisRunner` drives one axis sample by sample and returns the states
as float64 arrays in SI units (r, u, a, eps), for the lockstep tests and for
hil_sim.
"""

from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from .emit_c import cdef_of

CC = os.environ.get("CC", "gcc")
STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O2"]
SANITIZE = ["-fsanitize=undefined,address", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g"]


def build(files: dict[str, str], workdir: str | Path, *, prefix: str = "accelnav", sanitize: bool = False):
    import cffi

    workdir = Path(workdir).resolve()
    digest = hashlib.sha256(
        "\0".join(f"{k}\0{v}" for k, v in sorted(files.items())).encode() + bytes([sanitize])
    ).hexdigest()[:16]
    modname = f"_acn_{prefix}_{digest}"
    d = workdir / modname
    if modname in sys.modules:
        return sys.modules[modname]
    d.mkdir(parents=True, exist_ok=True)
    for name, text in files.items():
        (d / name).write_text(text)
    so = next(d.glob(f"{modname}*.so"), None)
    if so is None:
        # the generated C is compiled on its own with the strict flags (the cffi wrapper is not -pedantic clean)
        obj = d / f"{prefix}.o"
        cmd = [CC, *STRICT, "-fPIC", *(SANITIZE if sanitize else []), "-c", str(d / f"{prefix}.c"), "-o", str(obj)]
        subprocess.run(cmd, check=True, capture_output=True, text=True)
        ffi = cffi.FFI()
        ffi.cdef(cdef_of(files[f"{prefix}.h"]))
        ffi.set_source(
            modname,
            f'#include "{prefix}.h"',
            include_dirs=[str(d)],
            extra_objects=[str(obj)],
            extra_link_args=SANITIZE if sanitize else [],
        )
        so = Path(ffi.compile(tmpdir=str(d), verbose=False))
    spec = importlib.util.spec_from_file_location(modname, so)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    sys.modules[modname] = mod
    return mod


class AxisRunner:
    """One axis of a built module; ``run(raw...)`` -> dict of (N,) arrays."""

    def __init__(self, mod, manifest: dict | str, axis: int = 0, prefix: str = "accelnav"):
        if isinstance(manifest, str):
            manifest = json.loads(manifest)
        self.man = manifest
        self.ax = manifest["axes"][axis]
        self.name = self.ax["axis"]
        self.mod = mod
        self.ffi, self.lib = mod.ffi, mod.lib
        self.T = f"{prefix}_{self.name}"
        self.fixed = manifest["arith"] == "fixed"
        self.Ts = 1.0 / manifest["sample_rate_hz"]
        self.state = self.ffi.new(f"{self.T}_t *")
        self.out = self.ffi.new(f"{self.T}_out_t *")
        getattr(self.lib, f"{self.T}_init")(self.state)

    def frac(self, var: str) -> int:
        return self.ax["variables"][var]["frac"]

    def run(self, code=None, t1=None, t2=None) -> dict[str, np.ndarray]:
        step = getattr(self.lib, f"{self.T}_step")
        s = self.state
        if code is not None:
            raw = [np.asarray(code, dtype=np.int64).tolist()]
        else:
            raw = [np.asarray(t1, dtype=np.int64).tolist(), np.asarray(t2, dtype=np.int64).tolist()]
        n = len(raw[0])
        out = np.empty((n, 4))
        ok = np.empty(n, dtype=bool)
        if self.fixed:
            fr, fv, fa, fe = (self.frac(v) for v in ("r", "v", "a", "e"))
            sc = np.ldexp(1.0, [-fr, -fv, -fa, -fe]) * np.array([1.0, 1.0 / self.Ts, 1.0, 1.0])
            rows = []
            if len(raw) == 1:
                for k, c in enumerate(raw[0]):
                    ok[k] = step(s, c)
                    rows.append((s.r, s.v, s.a, s.e))
            else:
                for k, (a, b) in enumerate(zip(raw[0], raw[1], strict=True)):
                    ok[k] = step(s, a, b)
                    rows.append((s.r, s.v, s.a, s.e))
            # exact: the integers are converted in Python (int64 -> float loses nothing that matters here)
            ints = np.array(rows, dtype=object)
            for j in range(4):
                out[:, j] = [float(x) for x in ints[:, j]]
            out *= sc
        else:
            for k in range(n):
                ok[k] = step(s, *(r[k] for r in raw))
                out[k] = (s.r, s.u, s.a, s.e)
        return {"x": out, "valid": ok, "overflow": int(s.overflow)}
