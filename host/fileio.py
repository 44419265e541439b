"""Files from outside, read and written with bounds: what a path is, how much a file may make us allocate,
outputs that appear whole or not at all.

* :func:`check_input` refuses anything but a readable regular file before a byte is read (a FIFO or
  ``/dev/zero`` would block or fill memory), naming what the path is.
* :func:`load_npz` reads an NPZ only after its zip headers and each array's ``.npy`` header say it fits
  in :func:`input_limit`; pickles are never loaded.
* :func:`output_target` is the one output rule, :class:`OutputFile` (and :func:`atomic_output` over it)
  the one writer; every command and library writer goes through them:

  - a regular file, or nothing, is replaced atomically: written to ``.NAME.PID-TAG.part`` beside it
    (``O_CREAT | O_EXCL | O_NOFOLLOW``: never a planted link, never another run's file), then renamed;
  - a FIFO or a device is written through, never replaced (``/dev/null`` discards); ``-`` is stdout;
  - a symlink is followed: its target is replaced, the link stays;
  - an output that is one of the inputs (same device and inode, through links) is refused;
  - missing folders are created when the output is opened; a name too long is refused up front;
  - a second run writing the same output while the first writes is refused, naming the first's pid.

  A run holds an ``flock`` on each temporary file and scratch folder (:class:`TempFolder`) while it
  lives; the next writer in a folder removes those whose lock is free (their run ended, however: the
  kernel drops the lock with the process, which a reused pid cannot fake) and says so in one line.
  Creating an entry and judging others' happen under an flock on the folder. An OSError while writing
  (a full disk) becomes one line, with nothing left behind.
* :func:`excerpt` caps what a message echoes of the input.

The input limit is ``ACCELNAV_MAX_INPUT_BYTES`` (a whole number of bytes > 0; anything else is refused in
one line) if set, else :data:`MAX_INPUT_BYTES`, and never more than half the memory the machine has
available.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import io
import math
import os
import re
import secrets
import shutil
import stat
import tempfile
import zipfile
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
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


def env_count(name: str, unit: str) -> int | None:
    """The whole number > 0 the environment variable ``name`` sets, None when it is unset or empty; anything
    else is refused in one line that names it and what it takes (``unit``: what it counts)."""
    env = os.environ.get(name)
    if not env:
        return None
    try:
        k = int(env)
    except ValueError:
        k = 0
    if k < 1:
        raise UserError(f"{name}: got {excerpt(env)}; accepted: a whole number of {unit} > 0")
    return k


def input_limit() -> int:
    """How many bytes of decoded data one input may bring (see the module notes)."""
    limit = env_count("ACCELNAV_MAX_INPUT_BYTES", "bytes") or MAX_INPUT_BYTES
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


# --- outputs ---------------------------------------------------------------------------------------------------------

FILE, THROUGH, STDOUT = "file", "through", "stdout"
NAME_MAX = 255  # bytes of one name, where the file system does not say (os.pathconf)
PATH_MAX = 4096
_STEM_MAX = 150  # a temporary name holds at most this much of the output's name, then a hash of the rest
_TEMP = re.compile(r"^\.(?P<stem>.+)\.(?P<pid>\d+)-(?P<tag>[0-9a-f]{8})\.part$")
_TEMP_DIR = re.compile(r"^\.accelnav-(?P<what>[a-z]+)-(?P<pid>\d+)-(?P<tag>[0-9a-f]{8})$")


@dataclass(frozen=True)
class Output:
    """Where an output goes, as :func:`output_target` decided (see the module notes).

    ``given``: the name as the user wrote it (for messages); ``path``: what is written, symlinks followed
    (None for standard output); ``kind``: FILE (a regular file or nothing: replaced atomically), THROUGH
    (a FIFO or a device: written through, never replaced) or STDOUT (``-``)."""

    given: str
    path: Path | None
    kind: str
    flag: str = "--out"

    def __str__(self) -> str:
        return self.given

    @property
    def workdir(self) -> Path:
        """Where this output's temporary files go: beside a file (same file system: the rename is atomic),
        else the temporary folder (a device's folder, /dev say, is no place for them)."""
        return self.path.parent if self.kind == FILE else Path(tempfile.gettempdir())


def _name_max(folder: Path) -> int:
    existing = next((a for a in (folder, *folder.parents) if a.is_dir()), Path("."))
    try:
        return os.pathconf(existing, "PC_NAME_MAX")
    except (OSError, ValueError):
        return NAME_MAX


def _check_names(path: Path, flag: str) -> None:
    text = os.fsencode(str(path))
    if len(text) >= PATH_MAX:
        raise UserError(f"{flag}: a path of {len(text)} bytes; at most {PATH_MAX - 1}")
    limit = _name_max(path.parent)
    for part in path.parts:
        if len(os.fsencode(part)) > limit:
            raise UserError(
                f"{flag}: {excerpt(part, 40)}: a name of {len(os.fsencode(part))} bytes; at most {limit} here"
            )


def written_through(path: Path, mode: int) -> bool:
    """The rule's test for what is written through, never replaced: a FIFO or a device (``mode``: its stat)."""
    return stat.S_ISFIFO(mode) or stat.S_ISCHR(mode) or stat.S_ISBLK(mode)


def output_target(
    path: str | Path, flag: str = "--out", *, inputs: Iterable[str | Path | None] = (), stdout: bool | str = True
) -> Output:
    """The one output rule: what writing ``path`` will do, or a one-line UserError before any work.

    ``-`` is standard output when ``stdout`` is True (a string instead says why this output cannot be).
    A symlink is followed: its target is what is replaced (the link stays). An existing target must be a
    regular file (replaced atomically), a FIFO or a device (written through); a directory, a socket, a
    symlink loop are refused, and so is a target that is one of ``inputs`` (the same file by device and
    inode, through links). Missing folders on the way are created when the output is opened, so the
    nearest existing one must be a folder. A name longer than the file system takes is refused here.
    """
    if isinstance(path, Output):
        return path
    given = str(path)
    if given == "-":
        if stdout is True:
            return Output(given, None, STDOUT, flag)
        raise UserError(f"{flag}: '-' (standard output) is not accepted here: {stdout or 'give a file name'}")
    if not given:
        raise UserError(f"{flag}: an empty name; give a file name")
    p = Path(path)
    _check_names(p, flag)
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        if exc.errno == errno.ENOTDIR:  # a file on the way where a folder should be
            parent = next((a for a in p.parents if a.exists() and not a.is_dir()), p.parent)
            raise UserError(f"{flag}: {given}: {parent} is not a directory") from None
        raise UserError(f"{flag}: {given}: cannot use: {exc.strerror or exc}") from None
    target = p
    if st is not None and stat.S_ISLNK(st.st_mode):
        try:
            st = os.stat(p)
        except FileNotFoundError:
            st = None  # a dangling link: its target is created
        except OSError as exc:
            why = "a symlink loop" if exc.errno == errno.ELOOP else exc.strerror or str(exc)
            raise UserError(f"{flag}: {given}: {why}; give a file name") from None
        target = Path(os.path.realpath(p))
        _check_names(target, flag)
    if st is None:
        parent = next((a for a in target.parents if a.exists()), None)
        if parent is not None and not parent.is_dir():
            raise UserError(f"{flag}: {given}: {parent} is not a directory")
        return Output(given, target, FILE, flag)
    if stat.S_ISDIR(st.st_mode):
        raise UserError(f"{flag}: {given} is a directory; give a file name")
    if written_through(target, st.st_mode):
        # opened by the name given, the kernel following any link: a link's text may name no path
        # (/dev/stdout -> /proc/self/fd/1 -> "pipe:[...]")
        return Output(given, p, THROUGH, flag)
    if not stat.S_ISREG(st.st_mode):
        raise UserError(f"{flag}: {given}: {_what(st.st_mode)}; give a file name")
    for src in inputs:
        if src is None or str(src) == "-":
            continue
        try:
            same = os.path.samefile(target, src)
        except (OSError, ValueError):
            continue
        if same:
            raise UserError(f"{flag}: {given} is the input {src} (the same file); give another name")
    return Output(given, target, FILE, flag)


WRITE_FAILURES = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO)


def write_failure(exc: OSError) -> bool:
    """An OSError that says the disk took no more (full, over quota, too big, failing): said in one line by
    the writer; other OSErrors (a reader's, say) are not the output's to explain."""
    return exc.errno in WRITE_FAILURES


def free_bytes(folder: str | Path) -> int:
    """Free disk where files in ``folder`` will go: of its nearest existing ancestor (it may not exist yet)."""
    folder = Path(folder).absolute()
    existing = next((a for a in (folder, *folder.parents) if a.is_dir()), Path("/"))
    return shutil.disk_usage(existing).free


def check_output(path: str | Path, flag: str = "--out", *, inputs: Iterable[str | Path | None] = ()) -> Path:
    """:func:`output_target`, for callers that keep the name: ``path``, or a one-line refusal before the work."""
    output_target(path, flag, inputs=inputs)
    return Path(path)


def check_output_folder(path: str | Path, flag: str) -> Path:
    """A folder the command writes files into (each by the output rule): refused if it names anything
    but a folder, or if its nearest existing ancestor is not one; created when the files are written."""
    p = Path(path)
    if str(path) == "-":
        raise UserError(f"{flag}: '-' names no folder; give one (the files are written into it)")
    _check_names(p, flag)
    if p.exists() and not p.is_dir():
        what = "a file" if p.is_file() else _what(os.stat(p).st_mode)
        raise UserError(f"{flag}: {p} is {what}; give a directory for the files it gets")
    parent = next((a for a in p.parents if a.exists()), None)
    if parent is not None and not parent.is_dir():
        raise UserError(f"{flag}: {p}: {parent} is not a directory")
    return p


def _owner_alive(path: Path, is_dir: bool) -> bool | None:
    """Whether the run that made a temporary entry still runs: it holds an flock on it while it lives (the
    kernel drops it when the process ends, however it ends, so a reused pid cannot fake it). None: cannot
    tell (a planted link, no permission): such an entry is neither removed nor taken for a writer."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | (os.O_DIRECTORY if is_dir else 0))
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    except OSError:
        return None
    finally:
        os.close(fd)


@contextmanager
def _folder_locked(folder: Path) -> Iterator[None]:
    """Creating a temporary entry and locking it, and judging others' entries, happen under an flock on the
    folder, so a cleaner never sees an entry in the instant between its creation and its owner's lock."""
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _leftovers(folder: Path) -> list[tuple[str, int, bool]]:
    """Temporary entries of accelnav runs in ``folder``: (name, owner pid, is a folder)."""
    found = []
    try:
        names = os.listdir(folder)
    except OSError:
        return found
    for name in names:
        m = _TEMP.match(name) or _TEMP_DIR.match(name)
        if m:
            found.append((name, int(m["pid"]), m.re is _TEMP_DIR))
    return found


def _clean(folder: Path) -> None:
    """Remove what runs that ended (killed, a power cut) left in ``folder``, and say so; call locked."""
    gone = []
    for name, pid, is_dir in _leftovers(folder):
        path = folder / name
        if os.path.islink(path) or _owner_alive(path, is_dir) is not False:
            continue
        if is_dir:
            shutil.rmtree(path, ignore_errors=True)
        else:
            _unlink(str(path))
        gone.append((name, pid))
    if gone:
        from accelnav.progress import note

        pids = ", ".join(sorted({str(p) for _, p in gone}))
        note(f"removed {len(gone)} leftover(s) of accelnav runs that ended (pid {pids}) from {folder}: "
             + ", ".join(excerpt(n, 60) for n, _ in gone))  # fmt: skip


def _stem(name: str) -> str:
    if len(name) <= _STEM_MAX:
        return name
    return name[: _STEM_MAX - 9] + "~" + hashlib.sha256(os.fsencode(name)).hexdigest()[:8]


def _tag() -> str:
    return secrets.token_hex(4)


def _create_temp(folder: Path, stem: str) -> tuple[int, Path]:
    """A new file ``.STEM.PID-TAG.part`` in ``folder``, created exclusively (never through a link) and
    flocked by us; a name taken (planted, or a clash) is passed over for a fresh tag."""
    for _ in range(16):
        tmp = folder / f".{stem}.{os.getpid()}-{_tag()}.part"
        try:
            fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
        except FileExistsError:
            continue
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return fd, tmp
    raise FileExistsError(errno.EEXIST, "no free temporary name", str(folder))


class OutputFile:
    """The one writer of an output (see :func:`output_target`): write to ``fd``, then :meth:`commit`
    (the output appears whole) or :meth:`abort` (nothing is left).

    FILE: a temporary ``.NAME.PID-TAG.part`` beside the target, exclusive and flocked while we live; a
    file being written by another live run is refused in one line (two runs never both claim one output);
    what ended runs left in the folder is removed first. THROUGH and STDOUT: written through as the bytes
    come; with ``seekable`` (a writer that writes at offsets) they go to an unnamed temporary file first,
    copied at the commit. ``fsync=False`` for a view redrawn a moment later (the live plot).
    """

    def __init__(self, out: Output | str | Path, *, seekable: bool = False, fsync: bool = True) -> None:
        self.out = out if isinstance(out, Output) else output_target(out)
        self.fsync = fsync
        self.tmp: Path | None = None
        self._sink = -1  # the FIFO, device or stdout a seekable temporary file is copied to
        self.fd = -1
        flag, given = self.out.flag, self.out.given
        try:
            if self.out.kind == FILE:
                folder = self.out.path.parent
                folder.mkdir(parents=True, exist_ok=True)
                stem = _stem(self.out.path.name)
                with _folder_locked(folder):
                    _clean(folder)
                    for name, pid, is_dir in _leftovers(folder):
                        m = _TEMP.match(name)
                        if not is_dir and m["stem"] == stem and _owner_alive(folder / name, False) is True:
                            raise UserError(f"{flag}: {given}: another run (pid {pid}) is writing it now; wait for "
                                            "it to finish or give another name")  # fmt: skip
                    self.fd, self.tmp = _create_temp(folder, stem)
            else:
                sink = os.dup(1) if self.out.kind == STDOUT else os.open(self.out.path, os.O_WRONLY | os.O_CLOEXEC)
                if seekable:
                    self._sink = sink
                    with tempfile.TemporaryFile() as anon:  # unnamed: a kill leaves nothing of it
                        self.fd = os.dup(anon.fileno())
                else:
                    self.fd = sink
        except UserError:
            raise
        except OSError as exc:
            raise UserError(f"{flag}: {given}: cannot create: {exc.strerror or exc}") from None

    def commit(self, *, replace: bool = True, keep_open: bool = False) -> None:
        """The output in place: renamed over the target (``replace=False``: only if none has appeared, else
        FileExistsError); ``keep_open``: ``fd`` stays open for more (the recorder's log, appended after)."""
        try:
            if self.out.kind == FILE:
                if self.fsync:
                    os.fsync(self.fd)
                if replace:
                    os.replace(self.tmp, self.out.path)
                else:
                    os.link(self.tmp, self.out.path)  # fails, whatever the target is, if it exists
                    os.unlink(self.tmp)
                self.tmp = None
            elif self._sink >= 0:
                os.lseek(self.fd, 0, os.SEEK_SET)
                while chunk := os.read(self.fd, 1 << 20):
                    write_all(self._sink, chunk)
        except FileExistsError:
            self.abort()
            raise
        except OSError as exc:
            self.abort()
            raise UserError(f"{self.out.flag}: {self.out.given}: cannot write: {exc.strerror or exc}") from None
        if not keep_open:
            self._close()

    def abort(self) -> None:
        if self.tmp is not None:
            _unlink(str(self.tmp))
            self.tmp = None
        self._close()

    def _close(self) -> None:
        for fd in (self.fd, self._sink):
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.fd = self._sink = -1

    def error(self, exc: OSError) -> UserError:
        """The one line for a write that failed (a full disk): said after :meth:`abort` removed the rest."""
        return UserError(f"{self.out.flag}: {self.out.given}: cannot write: {exc.strerror or exc}; nothing was left "
                         "behind")  # fmt: skip


class _Unseekable(io.RawIOBase):
    """A FIFO's, a device's or stdout's descriptor as a stream that cannot seek: a writer that would seek
    back (zipfile, numpy's savez) then writes straight through instead (a device's position lies: /dev/null
    stays at 0)."""

    def __init__(self, fd: int) -> None:
        self.fd = fd

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        return os.write(self.fd, b)

    def close(self) -> None:
        if not self.closed:
            os.close(self.fd)
        super().close()


def _through(fd: int, mode: str):
    buffered = io.BufferedWriter(_Unseekable(os.dup(fd)))
    return buffered if "b" in mode else io.TextIOWrapper(buffered)


@contextmanager
def atomic_output(
    path: str | Path | Output, mode: str = "wb", flag: str = "--out", *, inputs=(), fsync: bool = True
) -> Iterator:
    """``with atomic_output(p) as fh: fh.write(...)``: by the output rule (:func:`output_target`), a file
    appears complete on success, untouched on failure; a FIFO, a device or ``-`` is written through. An
    OSError while writing (a full disk) becomes one line, and nothing is left behind."""
    out = path if isinstance(path, Output) else output_target(path, flag, inputs=inputs)
    w = OutputFile(out, fsync=fsync)
    try:
        with os.fdopen(os.dup(w.fd), mode) if out.kind == FILE else _through(w.fd, mode) as fh:
            yield fh
            fh.flush()
    except OSError as exc:
        w.abort()
        raise w.error(exc) from None
    except BaseException:
        w.abort()
        raise
    w.commit()


class TempFolder:
    """A private folder ``.accelnav-WHAT-PID-TAG`` in ``folder`` (default: the temporary folder) for a run's
    scratch files (``path``), flocked while we live, removed by :meth:`close` (or the ``with``'s end); what
    ended runs left there is removed first, so the next run in the folder cleans up after a kill -9."""

    def __init__(self, what: str, folder: str | Path | None = None) -> None:
        base = Path(folder) if folder is not None else Path(tempfile.gettempdir())
        base.mkdir(parents=True, exist_ok=True)
        self.fd = -1
        with _folder_locked(base):
            _clean(base)
            for _ in range(16):
                path = base / f".accelnav-{what}-{os.getpid()}-{_tag()}"
                try:
                    os.mkdir(path, 0o700)
                    break
                except FileExistsError:
                    continue
            else:
                raise FileExistsError(errno.EEXIST, "no free temporary name", str(base))
            self.path = path
            self.fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)

    def close(self) -> None:
        if self.fd >= 0:
            shutil.rmtree(self.path, ignore_errors=True)
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> Path:
        return self.path

    def __exit__(self, *exc) -> None:
        self.close()


def _unlink(p: str) -> None:
    try:
        os.unlink(p)
    except OSError:
        pass


def write_text(path: str | Path, text: str, flag: str = "--out", *, inputs=()) -> Path:
    with atomic_output(path, "w", flag, inputs=inputs) as fh:
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


def write_all(fd: int, buf) -> None:
    """Write all of ``buf`` to ``fd`` at its position (a pipe, a device: what cannot seek)."""
    view = memoryview(buf).cast("B")
    while view:
        view = view[os.write(fd, view) :]


def pwrite_all(fd: int, buf, pos: int) -> None:
    """Write all of ``buf`` (any C-contiguous buffer) at byte ``pos`` of ``fd``, however the kernel splits it."""
    view = memoryview(buf).cast("B")
    while view:
        done = os.pwrite(fd, view, pos)
        view, pos = view[done:], pos + done
