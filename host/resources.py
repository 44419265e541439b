"""Where the installed package keeps its files, and where runs may write theirs.

Everything accelnav ships besides Python (the model files, the firmware's C
and its Makefile fragment, the smoother's C kernel) is package data of the
``accelnav`` distribution. It is found through :mod:`importlib.resources`,
the same way in the source checkout (an editable install maps the folders)
and in an installed wheel, never by walking up from a source file.

Build artefacts of a user's run (cffi modules, firmware images, generated C
kept between runs) go to :func:`cache_root`, never beside the package: an
installed package's folder is usually read-only and is shared by every user.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path


def package_dir(package: str) -> Path:
    """The folder of an ``accelnav`` subpackage that carries data (``accelnav.models``, ...).

    The package is installed as plain files (setuptools never zips it), so the
    traversable is a real folder; that is checked rather than assumed.
    """
    root = resources.files(package)
    path = Path(str(root))
    if not path.is_dir():
        raise RuntimeError(f"{package}: package data is not a folder on disk ({root!r}); reinstall accelnav")
    return path


def models_dir() -> Path:
    """The shipped model files (``adxl250_default.toml`` is the embedded default)."""
    return package_dir("accelnav.models")


def example_path(name: str) -> Path:
    """A file shipped to try accelnav with, by name: a model (``foot_imu.toml``, ``adxl250_default.toml``, ...) or
    an example recording (``walk.csv``: 20 s of a simulated walk as a phone app writes it, a millisecond clock and
    two level horizontal axes in g with gravity removed, at the 200 Hz of ``foot_imu.toml``; ``walk_fixes.csv``:
    three position fixes per axis of it; ``phone_move.zip``: a phone logger's export, Sensor Logger's Android layout,
    of a tilted, turning phone moved 1 m along x and 0.5 m along y at 200 Hz). UserError, listing the names, for any
    other."""
    from accelnav.errors import UserError

    folders = (models_dir(), models_dir() / "examples")
    shipped = sorted(p.name for folder in folders for p in folder.iterdir() if p.suffix in (".toml", ".csv", ".zip"))
    if name not in shipped:
        raise UserError(f"example {name!r}: not shipped; accepted: {', '.join(shipped)}")
    return next(folder / name for folder in folders if (folder / name).is_file())


def firmware_dir() -> Path:
    """The firmware's sources: ``src/``, ``boards/`` and ``firmware.mk``."""
    return package_dir("accelnav.firmware")


def cache_root() -> Path:
    """Where runs keep what they build: ``$ACCELNAV_CACHE_DIR``, else ``$XDG_CACHE_HOME/accelnav``
    (``~/.cache/accelnav``)."""
    env = os.environ.get("ACCELNAV_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "accelnav"


THREADS_ENV = "ACCELNAV_THREADS"


def threads() -> int:
    """Threads a run may keep busy at once (its axes' passes, the CSV parser): ``$ACCELNAV_THREADS`` (a whole
    number >= 1), else 1 (one thing after the other); never more than ``os.cpu_count()``. Refused in one
    line (UserError) when set to anything else. One by default: on a machine whose CPUs others share, two
    threads took more CPU and no less wall time than one (smooth NPZ at 1e7, 2 CPUs under a load of 3-5:
    3.8-4.9 s of CPU and 4.2-5.7 s wall on two threads, 3.2-3.8 s and 3.6-4.6 s on one, measured)."""
    from accelnav.fileio import env_count

    return min(env_count(THREADS_ENV, "threads") or 1, os.cpu_count() or 1)


# glibc's settings a user may give in the environment: any of them set, reuse_freed_memory leaves glibc alone
MALLOC_ENV = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_", "MALLOC_ARENA_MAX")
# glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD, _M_ARENA_MAX = -1, -3, -8
REUSE_BLOCK = 32 << 20  # blocks up to this size come from (and go back to) the heap: glibc's largest setting
REUSE_KEEP = 128 << 20  # freed memory kept at the heap's top for the next block, not given back to the system


def reuse_freed_memory() -> bool:
    """Ask glibc's malloc to reuse freed memory for a run's chunk-sized arrays (a chunk's input, its temporary
    arrays, a block of the input's checks: 1-30 MB, allocated and freed again for every chunk) instead of
    mapping fresh pages for each. By default it maps every block over its threshold anew and unmaps it on
    free, so each chunk's arrays were fresh pages, zeroed by the kernel: at 1e7 samples about 1 s of the
    2 s of system time of `accelnav smooth` (bench/speed/bench_smooth_e2e.py; 28 MB more peak RSS).
    Called once by the command (a process of its own) and by the fleet's workers and
    :func:`accelnav.data.smoothing.smooth_batch`, whose processes are given to the fleet; any other library
    call leaves the host's allocator alone.
    One arena for every thread: the axes' and the CSV parser's threads (:func:`threads`) then reuse the same
    freed blocks, where an arena per thread mapped and trimmed its own (smooth CSV at 1e7 on two threads:
    3.7-4.8 s of system time against 1.7-2.4 with one arena, measured).
    False where it does not apply: no glibc, or the user set MALLOC_MMAP_THRESHOLD_, MALLOC_TRIM_THRESHOLD_
    or MALLOC_ARENA_MAX (theirs stand)."""
    import ctypes
    import sys

    if not sys.platform.startswith("linux") or any(k in os.environ for k in MALLOC_ENV):
        return False
    try:
        libc = ctypes.CDLL(None)
        gnu = libc.gnu_get_libc_version  # glibc's own: musl's mallopt is a stub that does nothing
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    del gnu
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return all(bool(mallopt(p, v)) for p, v in ((_M_MMAP_THRESHOLD, REUSE_BLOCK), (_M_TRIM_THRESHOLD, REUSE_KEEP),
                                                 (_M_ARENA_MAX, 1)))  # fmt: skip
