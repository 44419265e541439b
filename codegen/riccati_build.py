"""The Riccati kernel (csrc/riccati.c) as the extension ``accelnav.codegen._riccati``.

setup.py names this file in ``cffi_modules``, so the kernel is compiled when
the wheel (or an editable install) is built, and ``accelnav codegen`` runs it
with no C compiler on the user's machine. cffi runs this file on its own (not
as part of the package), so it imports nothing from accelnav;
:mod:`accelnav.codegen.gains` imports it for :func:`kernel_cdef`,
:func:`source_hash` and :data:`FLAGS`.

The kernel must give the very same doubles as its Python twin, so it is
compiled here with the flags of the run-time build (:data:`FLAGS`: ISO C99, no
contraction, no fast math). They apply to cffi's wrapper too, which is not
``-pedantic -Werror`` clean, so the warnings-as-errors flags are left to the
run-time build (they change no generated code).

The module carries the sha256 of the C it was built from
(``acn_riccati_source()``): gains uses it only when that matches the C beside
it, so an edited kernel in a source checkout is never served by a stale build.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

MODULE = "accelnav.codegen._riccati"
KERNEL_FILES = ("riccati.c", "riccati.h")
# the flags that decide the doubles: ISO C99 (no excess precision), no FMA contraction, no fast math
FLAGS = ("-std=c99", "-O2", "-ffp-contract=off", "-fno-fast-math")


def source_hash(csrc: Path) -> str:
    """sha256 of the kernel's C and header, as hex."""
    h = hashlib.sha256()
    for name in KERNEL_FILES:
        h.update((csrc / name).read_bytes())
    return h.hexdigest()


def kernel_cdef(header: str) -> str:
    """The declarations between the ACN-CDEF markers of riccati.h."""
    a = header.index("/* ACN-CDEF-BEGIN */")
    b = header.index("/* ACN-CDEF-END */")
    return header[a:b].split("\n", 1)[1]


def ffibuilder():
    import cffi

    # paths relative to the project root (setup.py's folder), as setuptools wants them
    csrc = Path(__file__).parent / "csrc"
    ffi = cffi.FFI()
    ffi.cdef(kernel_cdef((csrc / "riccati.h").read_text()) + "const char *acn_riccati_source(void);\n")
    ffi.set_source(
        MODULE,
        f'#include "riccati.h"\nstatic const char *acn_riccati_source(void) {{ return "{source_hash(csrc)}"; }}\n',
        sources=[str(csrc / "riccati.c")],
        include_dirs=[str(csrc)],
        extra_compile_args=[*FLAGS, "-Wall", "-Wextra"],
        libraries=["m"],
    )
    return ffi
