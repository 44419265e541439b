"""Files from outside, read and written with bounds: what a path is, how much a file may make us allocate,
outputs that appear whole or not at all.

* :func:`check_input` refuses anything but a readable regular file before a byte is read (a FIFO or
  ``/dev/zero`` would block or fill memory), naming what the path is.
* :func:`load_npz` reads an NPZ only after its zip headers and each array's ``.npy`` header say it fits
  in :func:`input_limit`; pickles are never loaded.
* :func:`atomic_output` writes to a temporary name in the target folder and renames on success, so a
  kill or an error never leaves a partial file under the name the user gave.
* :func:`excerpt` caps what a message echoes of the input.

The input limit is ``ACCELNAV_MAX_INPUT_BYTES`` (bytes) if set, else :data:`MAX_INPUT_BYTES`, and never
more than half the memory the machine has available.
"""

from __future__ import annotations

import errno
import math
import os
import stat
import tempfile
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from tokenize import TokenError

from accelnav.errors import UserError

MAX_INPUT_BYTES = 1 << 30  # decoded arrays of one input file: 1 GiB is 134 M float64 samples
EXCERPT_CHARS = 80


def excerpt(text, n: int = EXCERPT_CHARS) -> str:
    """``repr`` of ``text`` cut to about ``n`` characters: a message never echoes a whole file."""
    r = repr(text)
    return r if len(r) <= n else r[: n - 3] + "..."


def _available_bytes() -> int | None:
    try:
        with open("/proc/meminfo", "rb") as fh:
            for line in fh:
                if line.startswith(b"MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def input_limit() -> int:
    """How many bytes of decoded data one input may bring (see the module notes)."""
    limit = MAX_INPUT_BYTES
    env = os.environ.get("ACCELNAV_MAX_INPUT_BYTES")
    if env:
        try:
            limit = int(env)
        except ValueError:
            raise UserError(f"ACCELNAV_MAX_INPUT_BYTES: got {excerpt(env)}; accepted: a number of bytes") from None
    avail = _available_bytes()
    return min(limit, avail // 2) if avail else limit


def _size(n: int) -> str:
    return f"{n / (1 << 30):.3g} GiB" if n >= 1 << 30 else f"{n / (1 << 20):.3g} MiB"


def _what(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def check_input(path: str | Path) -> Path:
    """``path`` if it is a regular file we may read; else a one-line UserError saying what it is."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            raise UserError(f"{path}: a broken symlink (its target does not exist)") from None
        raise UserError(f"{path}: no such file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise UserError(f"{path}: a symlink loop; a file is expected") from None
        raise UserError(f"{path}: cannot read: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        raise UserError(f"{path}: {_what(st.st_mode)}; a file is expected")
    try:
        open(path, "rb").close()
    except OSError as exc:
        raise UserError(f"{path}: cannot read: {exc.strerror or exc}") from None
    return path


def check_output(path: str | Path, flag: str = "--out") -> Path:
    """Refuse, before any work, an output name that cannot become a file (a directory, a file as folder)."""
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{flag}: {path} is a directory; give a file name")
    # the nearest ancestor of the user's output that exists must be a folder
    parent = next((a for a in path.parents if a.exists()), None)
    if parent is not None and not parent.is_dir():
        raise UserError(f"{flag}: {path}: {parent} is not a directory")
    return path


@contextmanager
def atomic_output(path: str | Path, mode: str = "wb", flag: str = "--out") -> Iterator:
    """``with atomic_output(p) as fh: fh.write(...)``: ``p`` appears complete on success, untouched on failure.

    The temporary file sits beside ``p`` (same file system, so the rename is atomic) under a hidden
    name; it is removed on any error. An OSError while writing (a full disk) becomes one line.
    """
    path = check_output(path, flag)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    except OSError as exc:
        raise UserError(f"{flag}: {path}: cannot create: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, mode) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp's 0600 is not what a plain open would give
        os.replace(tmp, path)
    except OSError as exc:
        _unlink(tmp)
        raise UserError(f"{flag}: {path}: cannot write: {exc.strerror or exc}") from None
    except BaseException:
        _unlink(tmp)
        raise


def _unlink(p: str) -> None:
    try:
        os.unlink(p)
    except OSError:
        pass


def write_text(path: str | Path, text: str, flag: str = "--out") -> Path:
    with atomic_output(path, "w", flag) as fh:
        fh.write(text)
    return Path(path)


def npz_members(path: str | Path, source: str | None = None) -> list[str]:
    """The array names of an NPZ (from its zip directory only), or a one-line refusal."""
    src = source or str(path)
    check_input(path)
    try:
        with zipfile.ZipFile(path) as zf:
            return [i.filename[:-4] for i in zf.infolist() if i.filename.endswith(".npy")]
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError):
        raise UserError(f"{src}: not an NPZ file (not a readable zip archive)") from None
    except OSError as exc:
        raise UserError(f"{src}: cannot read: {exc.strerror or exc}") from None


def load_npz(path: str | Path, source: str | None = None, then: str = "") -> dict:
    """Every array of an NPZ, each checked against :func:`input_limit` before it is inflated.

    Checked in turn: the zip directory's declared sizes (``file_size``, and its ratio to
    ``compress_size`` is then bounded by the limit too), each member's ``.npy`` header (an object dtype
    is refused: no pickles), and ``shape * itemsize`` against the member's declared size, so neither a
    lying header nor a zip bomb allocates more than the limit. ``then`` ends the message for a file that is
    not a zip archive at all (what the caller expected).
    """
    from numpy.lib import format as npy

    src = source or str(path)
    check_input(path)
    limit = input_limit()
    out = {}
    opened = False
    try:
        with zipfile.ZipFile(path) as zf:
            opened = True
            infos = [i for i in zf.infolist() if i.filename.endswith(".npy")]
            total = sum(i.file_size for i in infos)
            if total > limit:
                big = max(infos, key=lambda i: i.file_size)
                raise UserError(
                    f"{src}: its arrays declare {_size(total)} uncompressed ({excerpt(big.filename[:-4])}: "
                    f"{_size(big.file_size)}); accepted: at most {_size(limit)} (ACCELNAV_MAX_INPUT_BYTES)"
                )
            for info in infos:
                name = info.filename[:-4]
                with zf.open(info) as fh:
                    try:
                        version = npy.read_magic(fh)
                        reader = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
                        shape, _, dtype = reader(fh)
                    except (ValueError, SyntaxError, TokenError) as exc:  # numpy's header parser lets the last two out
                        raise UserError(
                            f"{src}: array {excerpt(name)} is not a .npy array: {excerpt(str(exc))}"
                        ) from None
                    head = fh.tell()
                if dtype.hasobject:
                    raise UserError(f"{src}: array {excerpt(name)} holds Python objects; pickles are not loaded")
                nbytes = math.prod(shape) * dtype.itemsize
                if nbytes > info.file_size - head:
                    raise UserError(
                        f"{src}: array {excerpt(name)} declares shape {shape} ({_size(nbytes)}) but its member "
                        f"holds {_size(info.file_size)}: the file is damaged"
                    )
                with zf.open(info) as fh:
                    out[name] = npy.read_array(fh, allow_pickle=False)
    except UserError:
        raise
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, ValueError, NotImplementedError) as exc:
        if not opened:
            raise UserError(f"{src}: not an NPZ file (not a readable zip archive){then}") from None
        raise UserError(f"{src}: damaged NPZ: {excerpt(str(exc))}") from None
    except OSError as exc:
        raise UserError(f"{src}: cannot read: {exc.strerror or exc}") from None
    return out


def pread_exact(fd: int, buf, pos: int, what: str = "store", error: type[Exception] = OSError) -> None:
    """Fill ``buf`` (any buffer, e.g. a C-contiguous array) from byte ``pos`` of ``fd``; a file that ends
    first raises ``error`` naming ``what`` (a store truncated under us, say)."""
    view = memoryview(buf).cast("B")
    while view:
        got = os.preadv(fd, [view], pos)
        if got <= 0:
            raise error(f"{what}: short read at byte {pos}")
        view, pos = view[got:], pos + got


def pwrite_all(fd: int, buf, pos: int) -> None:
    """Write all of ``buf`` (any C-contiguous buffer) at byte ``pos`` of ``fd``, however the kernel splits it."""
    view = memoryview(buf).cast("B")
    while view:
        done = os.pwrite(fd, view, pos)
        view, pos = view[done:], pos + done
