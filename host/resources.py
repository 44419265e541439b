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
