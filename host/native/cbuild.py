"""Compile hand-written C into a Python extension with cffi (API mode), once per source text.

:func:`build_module` takes C sources, the declarations cffi should expose
(``cdef``) and a module stem, and returns the imported module (``.ffi``,
``.lib``). The module name carries a hash of everything that goes into the
build (sources, headers, cdef, flags, Python and cffi versions), so an edit
gives a new module and an unchanged source is compiled once per cache
folder. The compile happens in a private temporary folder; the finished
``.so`` is kept as a sealed cache entry (:mod:`accelnav.cachefile`: an
HMAC under the user's key, written whole by a rename, built under a lock
so two processes needing it compile it once).

A cached module is code: its bytes are read whole and verified before any
of them is loaded, then loaded from those very bytes (a sealed memfd on
Linux), never from the cache file again, so a module edited, swapped or
truncated in the cache is rebuilt (one line on stderr), never run, and
cannot raise SIGBUS under a running process.

Cache folder: ``cffi/`` under :func:`accelnav.resources.cache_root`
(``$ACCELNAV_CACHE_DIR``, else ``~/.cache/accelnav``): never inside the
installed package or the source checkout.

This is deliberately generic (it knows nothing about filters) so that the
hand-written kernels in host/estimate/csrc and the generated code of codegen can share
one builder.
"""

from __future__ import annotations

import fcntl
import hashlib
import importlib.machinery
import importlib.util
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile
from collections.abc import Sequence
from pathlib import Path

from accelnav.cachefile import cached
from accelnav.resources import cache_root, firmware_dir


def _fw_warn() -> tuple[str, ...]:
    """FW_WARN of firmware/parts.mk (package data): the one definition of the strict flags, which the
    firmware's make files include and every Python build reads from here."""
    text = (firmware_dir() / "parts.mk").read_text()
    found = re.search(r"^FW_WARN\s*:=[ \t]*(.*?)\s*$", text, re.M)
    if found is None:
        raise RuntimeError(f"{firmware_dir() / 'parts.mk'}: no FW_WARN line; reinstall accelnav")
    return tuple(found[1].split())


# the warnings every strict build of accelnav's C uses (firmware, generated filter, kernels, harnesses)
STRICT_WARN = _fw_warn()
STRICT_FLAGS = (*STRICT_WARN, "-O2")
# for a build that links a board's startup.c (not ours: its vector table casts function pointers to
# void *, which -pedantic refuses), as firmware.mk builds that file
BOARD_WARN = tuple(f for f in STRICT_WARN if f != "-pedantic")


MAX_MODULE_BYTES = 256 << 20  # a cached module larger than this is no module of ours (ours: tens of kB to a few MB)


class BuildError(RuntimeError):
    """A C build that could not be done: no compiler (one line naming the Debian package), or a compile error."""


def cache_dir() -> Path:
    """Where built modules live (see the module docstring)."""
    return cache_root() / "cffi"


def build_module(
    stem: str,
    cdef: str,
    sources: dict[str, str],
    *,
    main: str | Sequence[str],
    preamble: str | None = None,
    extra_compile_args: Sequence[str] = STRICT_FLAGS,
    extra_link_args: Sequence[str] = (),
    workdir: str | Path | None = None,
):
    """Build (or reuse) and import a cffi API-mode module.

    ``sources`` maps file names to text (``.c`` and ``.h`` files, written side
    by side); ``main`` is the ``.c`` file (or the list of them) compiled into
    the module with ``extra_compile_args``. The cffi wrapper starts with
    ``preamble`` (default: ``#include`` of the first main file's header).
    ``extra_link_args`` go to the final link (e.g. a sanitizer's runtime).
    ``cdef`` is the declaration block cffi exposes. Returns the module.
    """
    import cffi

    mains = [main] if isinstance(main, str) else list(main)
    if preamble is None:
        header = Path(mains[0]).with_suffix(".h").name
        preamble = f'#include "{header}"' if header in sources else ""
    key = "\0".join(
        [cdef, preamble, *mains, *(f"{k}\0{v}" for k, v in sorted(sources.items()))]
        + [*extra_compile_args, "--link", *extra_link_args, sys.version, cffi.__version__, platform.machine()]
        + [os.environ.get("CC", "cc")]
    )
    modname = f"_{stem}_{hashlib.sha256(key.encode()).hexdigest()[:16]}"
    if modname in sys.modules:
        return sys.modules[modname]
    root = Path(workdir) if workdir is not None else cache_dir()
    suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"

    def compile_so() -> bytes:
        root.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{modname}.", dir=root))
        try:
            for name, text in sources.items():
                (tmp / name).write_text(text)
            # Our C is compiled on its own with the strict flags; cffi's generated wrapper
            # (which is not -pedantic clean) is then compiled with the defaults and linked to it.
            cc = os.environ.get("CC", "cc")
            if shutil.which(shlex.split(cc)[0] if cc.strip() else "cc") is None:
                raise BuildError(f"C compiler {cc!r} not found: building {stem} needs one (Debian: gcc)")
            objs = []
            for name in mains:
                obj = tmp / (Path(name).stem + ".o")
                cmd = [cc, *extra_compile_args, "-fPIC", "-c", str(tmp / name), "-o", str(obj), f"-I{tmp}"]
                done = subprocess.run(cmd, capture_output=True, text=True)
                if done.returncode != 0:
                    raise BuildError(f"{' '.join(cmd)} failed:\n{done.stderr}")
                objs.append(str(obj))
            # cffi writes the wrapper's C; we compile and link it ourselves, as ffi.compile would through
            # setuptools, which Python 3.12 and later no longer carry (and a user's venv need not have).
            ffi = cffi.FFI()
            ffi.cdef(cdef)
            ffi.set_source(modname, preamble, compiler_verbose=0)  # no 'generating ...' on stdout
            wrapper = tmp / f"{modname}.c"
            ffi.emit_c_code(str(wrapper))
            built = tmp / f"{modname}{suffix}"
            cmd = [
                cc, "-O2", "-fPIC", "-shared", str(wrapper), *objs, f"-I{tmp}",
                f"-I{sysconfig.get_paths()['include']}", "-o", str(built), *extra_link_args, "-lm",
                *(["-undefined", "dynamic_lookup"] if sys.platform == "darwin" else []),
            ]  # fmt: skip
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0:
                raise BuildError(f"{' '.join(cmd)} failed:\n{done.stderr}")
            return built.read_bytes()
        finally:
            shutil.rmtree(tmp, ignore_errors=True)

    # the module's bytes, verified (sealed with the user's key) before anything of them is loaded
    data = cached(root / f"{modname}{suffix}.sealed", compile_so, limit=MAX_MODULE_BYTES)
    mod = _load_extension(modname, data, suffix)
    sys.modules[modname] = mod
    return mod


# memfds of the modules loaded from memory: kept open for the process's life, since the dynamic loader
# knows a loaded library by its path and a closed descriptor's number (hence its /proc path) is reused
_loaded_fds: list[int] = []


def _load_extension(modname: str, data: bytes, suffix: str):
    """Import an extension module from verified bytes, without reading its file again: on Linux from a
    sealed memfd (nobody can change or truncate it while it is mapped); elsewhere from a copy in a private
    temporary folder. Either way the bytes loaded are the bytes verified."""
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create(modname, os.MFD_CLOEXEC | os.MFD_ALLOW_SEALING)
        try:
            view = memoryview(data)
            while view:
                view = view[os.write(fd, view) :]
            seals = fcntl.F_SEAL_SHRINK | fcntl.F_SEAL_GROW | fcntl.F_SEAL_WRITE | fcntl.F_SEAL_SEAL
            fcntl.fcntl(fd, fcntl.F_ADD_SEALS, seals)
            mod = _import_from(modname, f"/proc/self/fd/{fd}")
        except (OSError, ImportError):
            os.close(fd)  # a kernel that will not map a memfd executable: the private copy below
        else:
            _loaded_fds.append(fd)
            return mod
    with tempfile.TemporaryDirectory(prefix="accelnav-so-") as tmp:  # mode 0700: only this user can change it
        path = Path(tmp) / f"{modname}{suffix}"
        path.write_bytes(data)
        return _import_from(modname, str(path))  # the mapping outlives the file, which goes with the folder


def _import_from(modname: str, path: str):
    loader = importlib.machinery.ExtensionFileLoader(modname, path)
    spec = importlib.util.spec_from_file_location(modname, path, loader=loader)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
