"""The wire kernel (csrc/acnwire.c) as the extension ``accelnav.link._acnwire``.

setup.py names this file in ``cffi_modules``, so the kernel is compiled when
the wheel (or an editable install) is built and the telemetry decoder takes
its fast path with no C compiler on the user's machine. cffi runs this file on
its own (not as part of the package), so it imports nothing from accelnav;
:mod:`accelnav.link.wirekernel` imports it for :func:`kernel_cdef` and
:func:`source_hash`.

The module carries the sha256 of the C it was built from
(``acnw_source()``): wirekernel uses it only when that matches the C beside
it, so an edited kernel in a source checkout is never served by a stale build.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

MODULE = "accelnav.link._acnwire"
KERNEL_FILES = ("acnwire.c", "acnwire.h")


def source_hash(csrc: Path) -> str:
    """sha256 of the kernel's C and header, as hex."""
    h = hashlib.sha256()
    for name in KERNEL_FILES:
        h.update((csrc / name).read_bytes())
    return h.hexdigest()


def kernel_cdef(header: str) -> str:
    """The declarations between the ACN-CDEF markers of acnwire.h."""
    a = header.index("/* ACN-CDEF-BEGIN */")
    b = header.index("/* ACN-CDEF-END */")
    return header[a:b].split("\n", 1)[1]


def ffibuilder():
    import cffi

    # paths relative to the project root (setup.py's folder), as setuptools wants them
    csrc = Path(__file__).parent / "csrc"
    ffi = cffi.FFI()
    ffi.cdef(kernel_cdef((csrc / "acnwire.h").read_text()) + "const char *acnw_source(void);\n")
    ffi.set_source(
        MODULE,
        f'#include "acnwire.h"\nstatic const char *acnw_source(void) {{ return "{source_hash(csrc)}"; }}\n',
        sources=[str(csrc / "acnwire.c")],
        include_dirs=[str(csrc)],
        extra_compile_args=["-std=c99", "-O2"],
    )
    return ffi
