"""Build generated C into a Python module with cffi (API mode).

``build(files, workdir)`` compiles the generated ``PREFIX.c`` with the
declarations cut from ``PREFIX.h`` (so the C and Python cannot drift) and
returns the imported module (``.ffi``, ``.lib``). Modules are keyed by the
hash of the generated text and cached in ``workdir``: the same model builds
once. ``sanitize=True`` adds -fsanitize=undefined,address (the test process
must then preload libasan; tests/codegen/test_codegen.py builds its sanitized run as a program instead).

:class:`AxisRunner` drives one axis sample by sample and returns the states
as float64 arrays in SI units (r, u, a, eps), for the lockstep tests and for
hil_sim.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from accelnav.codegen.emit_c import cdef_of
from accelnav.native.cbuild import STRICT_FLAGS

STRICT = list(STRICT_FLAGS)
SANITIZE = ["-fsanitize=undefined,address", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer", "-g"]


def build(files: dict[str, str], workdir: str | Path, *, prefix: str = "accelnav", sanitize: bool = False):
    """Compile ``PREFIX.c`` with the strict flags and the declarations cut from ``PREFIX.h``, through the
    project's one cffi builder (accelnav.native.cbuild), cached in ``workdir`` by the hash of the generated text."""
    from accelnav.native.cbuild import build_module

    return build_module(
        f"acn_{prefix}",
        cdef_of(files[f"{prefix}.h"]),
        {k: v for k, v in files.items() if not k.endswith(".json")},
        main=f"{prefix}.c",
        extra_compile_args=STRICT + (SANITIZE if sanitize else []),
        extra_link_args=SANITIZE if sanitize else [],
        workdir=Path(workdir).resolve(),
    )


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
            # the gain schedule carries eb = eps - e_state_offset (emit_c._gs_defines): eps = eb + offset
            eoff = self.ax.get("e_state_offset")
            ef = "e" if eoff is None else "eb"
            eoff = eoff or 0
            if len(raw) == 1:
                for k, c in enumerate(raw[0]):
                    ok[k] = step(s, c)
                    rows.append((s.r, s.v, s.a, getattr(s, ef) + eoff))
            else:
                for k, (a, b) in enumerate(zip(raw[0], raw[1], strict=True)):
                    ok[k] = step(s, a, b)
                    rows.append((s.r, s.v, s.a, getattr(s, ef) + eoff))
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
