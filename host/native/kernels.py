"""The C kernels compiled into the package: the smoother's, codegen's Riccati recursion and schedule
search, the telemetry decoder's frame kernel and the CSV reader's number parser.

setup.py names :func:`smoother`, :func:`riccati`, :func:`wire` and :func:`csvnum` in ``cffi_modules``, so each kernel
is compiled when the wheel (or an editable install) is built, and a user's machine needs no C compiler
for them. cffi runs this file on its own, not as part of the package, so at module level it imports
nothing but the standard library (cffi and the project's builder are imported inside the functions).

Every prebuilt module carries the sha256 of the C it was built from (its ``stamp`` function):
:func:`prebuilt` serves it only when that equals the C beside it, so an edited kernel in a source
checkout is never served by a stale build; :func:`build` then compiles the same C through the
project's cffi builder (:func:`accelnav.native.cbuild.build_module`, cached on disk).

The Riccati kernel must give the very doubles of its Python twin, so its flags (:data:`RICCATI_FLAGS`:
ISO C99, no contraction, no fast math) are those of the run-time build too. They apply to cffi's wrapper
in the wheel build, which is not ``-pedantic -Werror`` clean, so the warnings-as-errors flags are left to
the run-time build (they change no generated code).
"""

from __future__ import annotations

import hashlib
import importlib
from pathlib import Path
from typing import NamedTuple

# the flags that decide the Riccati kernel's doubles: ISO C99 (no excess precision), no FMA contraction,
# no fast math
RICCATI_FLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math")


class Kernel(NamedTuple):  # not a dataclass: cffi runs this file outside sys.modules
    module: str  # the prebuilt extension's import name
    folder: str  # its csrc folder, from the project root (the wheel build)
    files: tuple[str, str]  # the C file and its header (the cdef between ACN-CDEF markers)
    stamp: str  # C function returning the sha256 of the C it was built from
    flags: tuple[str, ...]  # the wheel build's compile flags
    libraries: tuple[str, ...] = ()


SMOOTHER = Kernel(
    "accelnav.estimate._fastsmooth", "host/estimate/csrc", ("fastsmooth.c", "fastsmooth.h"),
    "acn_fastsmooth_source", ("-std=c99", "-O3"), ("m",),
)  # fmt: skip
RICCATI = Kernel(
    "accelnav.codegen._riccati", "codegen/csrc", ("riccati.c", "riccati.h"),
    "acn_riccati_source", (*RICCATI_FLAGS, "-Wall", "-Wextra"), ("m",),
)  # fmt: skip
WIRE = Kernel(
    "accelnav.link._acnwire", "host/link/csrc", ("acnwire.c", "acnwire.h"), "acnw_source", ("-std=c99", "-O2")
)
# the CSV body's numbers: correctly rounded like Python's float(), so no contraction and no fast math
CSVNUM = Kernel(
    "accelnav.data._csvnum", "host/data/csrc", ("csvnum.c", "csvnum.h"), "acsv_source", RICCATI_FLAGS, ("m",)
)  # fmt: skip


def source_hash(k: Kernel, csrc: Path) -> str:
    """sha256 of the kernel's C and header in ``csrc``, as hex."""
    h = hashlib.sha256()
    for name in k.files:
        h.update((csrc / name).read_bytes())
    return h.hexdigest()


def kernel_cdef(header: str) -> str:
    """The declarations between the ACN-CDEF markers of a kernel's header."""
    a = header.index("/* ACN-CDEF-BEGIN */")
    b = header.index("/* ACN-CDEF-END */")
    return header[a:b].split("\n", 1)[1]


def _ffibuilder(k: Kernel):
    import cffi

    # setuptools runs the build in the project root (setup.py's folder) and wants paths relative to it
    csrc = Path(k.folder)
    c, h = k.files
    ffi = cffi.FFI()
    ffi.cdef(kernel_cdef((csrc / h).read_text()) + f"const char *{k.stamp}(void);\n")
    ffi.set_source(
        k.module,
        f'#include "{h}"\nstatic const char *{k.stamp}(void) {{ return "{source_hash(k, csrc)}"; }}\n',
        sources=[str(csrc / c)],
        include_dirs=[str(csrc)],
        extra_compile_args=list(k.flags),
        libraries=list(k.libraries),
    )
    return ffi


def smoother():
    return _ffibuilder(SMOOTHER)


def riccati():
    return _ffibuilder(RICCATI)


def wire():
    return _ffibuilder(WIRE)


def csvnum():
    return _ffibuilder(CSVNUM)


def prebuilt(k: Kernel, csrc: Path):
    """The kernel's module compiled with the package, if it was built from the C in ``csrc``; else None."""
    try:
        mod = importlib.import_module(k.module)
    except ImportError:
        return None
    built = mod.ffi.string(getattr(mod.lib, k.stamp)()).decode()
    return mod if built == source_hash(k, csrc) else None


def build(k: Kernel, csrc: Path, flags, stem: str, *, required: bool = True):
    """The kernel built from ``csrc`` by the project's cffi builder (once per source, cached on disk).
    Where that cannot be done (no C compiler): :class:`accelnav.native.cbuild.BuildError` (or OSError),
    or None when not ``required`` (the caller then has a Python path)."""
    from accelnav.native.cbuild import BuildError, build_module

    c, h = k.files
    header = (csrc / h).read_text()
    try:
        return build_module(
            stem, kernel_cdef(header), {c: (csrc / c).read_text(), h: header}, main=c, extra_compile_args=flags
        )
    except (OSError, BuildError):
        if required:
            raise
        return None
