"""The smoother's C kernel (csrc/fastsmooth.c) as the extension ``accelnav.estimate._fastsmooth``.

setup.py names this file in ``cffi_modules``, so the kernel is compiled when
the wheel (or an editable install) is built and ``accelnav smooth`` needs no C
compiler at run time. cffi runs this file on its own (not as part of the
package), so it imports nothing from accelnav; :mod:`accelnav.estimate.fastsmooth`
imports it for :func:`kernel_cdef` and :func:`source_hash`.

The module carries the sha256 of the C it was built from
(``acn_fastsmooth_source()``): fastsmooth uses it only when that matches the
C beside it, so an edited kernel in a source checkout is never served by a
stale build (it is then compiled through the cffi builder instead).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import cffi

MODULE = "accelnav.estimate._fastsmooth"
KERNEL_FILES = ("fastsmooth.c", "fastsmooth.h")


def source_hash(csrc: Path) -> str:
    """sha256 of the kernel's C and header, as hex."""
    h = hashlib.sha256()
    for name in KERNEL_FILES:
        h.update((csrc / name).read_bytes())
    return h.hexdigest()


def kernel_cdef(header: str) -> str:
    """The declarations between the ACN-CDEF markers of fastsmooth.h."""
    a = header.index("/* ACN-CDEF-BEGIN */")
    b = header.index("/* ACN-CDEF-END */")
    return header[a:b].split("\n", 1)[1]


def ffibuilder() -> cffi.FFI:
    # paths relative to the project root (setup.py's folder), as setuptools wants them
    csrc = Path(__file__).parent / "csrc"
    ffi = cffi.FFI()
    ffi.cdef(kernel_cdef((csrc / "fastsmooth.h").read_text()) + "const char *acn_fastsmooth_source(void);\n")
    ffi.set_source(
        MODULE,
        '#include "fastsmooth.h"\n'
        f'static const char *acn_fastsmooth_source(void) {{ return "{source_hash(csrc)}"; }}\n',
        sources=[str(csrc / "fastsmooth.c")],
        include_dirs=[str(csrc)],
        extra_compile_args=["-std=c99", "-O3"],
        libraries=["m"],
    )
    return ffi
