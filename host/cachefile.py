"""Cache entries that cannot lie: sealed with a per-user secret, read whole, built under a lock.

What accelnav keeps between runs (compiled cffi modules, the generator's C text, the smoother's gains) is
read back from a folder that others may write: a CI cache restored from storage, a lab share, a folder a
tool truncated in place. Nothing from there is trusted for what it says it is. Every entry is

* **named by what it was built from** (the caller hashes sources, flags, versions, model numbers into the
  file name), so an edit of any input gives another entry;
* **sealed**: an HMAC-SHA256 over the entry's name and its bytes, under a secret of the user's that is
  kept outside the cache folder (:func:`key_path`). Editing an entry and recomputing a plain hash gets
  nowhere: without the secret no one can make a tag that :func:`read_sealed` accepts, and binding the name
  means a sealed entry moved to another entry's name is refused too;
* **read whole with read()**, never mapped, before anything looks at it, so a file truncated or rewritten
  while a run uses it can only fail the check (and be rebuilt), never raise SIGBUS;
* **built under a lock** (:func:`entry_lock`, ``flock`` on ``NAME.lock`` beside it): two processes
  needing one missing entry build it once; entries appear by an atomic rename, so a reader without the
  lock sees a whole entry or none.

A bad entry (damaged, truncated, sealed under another key, not a regular file) is rebuilt and said in one
line on stderr (:func:`cache_note`); a cache folder that cannot be written costs time, never a failure.

Trust model of a shared cache folder (``ACCELNAV_CACHE_DIR`` on a CI cache or a lab share): entries are
verified against the key of the user running accelnav, so an entry counts only if that key sealed it.
Someone who can write the folder but has not the key can delete entries, fill the disk, or replace an
entry with garbage or with another user's entry: each costs a rebuild and a line on stderr, never a
different result and never code that runs. Users who want to share built entries must share the key file
(``ACCELNAV_CACHE_KEY_FILE``); whoever holds the key can make entries everyone holding it will trust.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import hmac
import logging
import os
import stat
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from accelnav.errors import AccelnavWarning, UserError
from accelnav.resources import cache_root

_log = logging.getLogger(__name__)

MAGIC = b"ACNSEAL1"
TAG_BYTES = 32
HEAD = len(MAGIC) + TAG_BYTES
KEY_ENV = "ACCELNAV_CACHE_KEY_FILE"
LOCK_TIMEOUT_S = 900.0  # the longest build waited for (a sanitized firmware build takes minutes on a slow machine)

_secret: bytes | None = None
_ephemeral = False  # the key is this process's own (none could be read or made): entries are not kept


def key_path() -> Path:
    """The cache key: ``$ACCELNAV_CACHE_KEY_FILE``, else ``$XDG_CONFIG_HOME/accelnav/cache.key``
    (``~/.config/accelnav/cache.key``): never inside the cache folder, which others may write."""
    env = os.environ.get(KEY_ENV)
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CONFIG_HOME")
    return (Path(xdg) if xdg else Path.home() / ".config") / "accelnav" / "cache.key"


def _read_key(path: Path) -> bytes:
    """The 32 secret bytes of an existing key file (64 hex digits), after checking who can change it."""
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise UserError(f"cache key {path}: not a regular file; remove it (a new key is made on the next run)")
        if st.st_uid not in (os.geteuid(), 0) or st.st_mode & 0o022:
            raise UserError(
                f"cache key {path}: writable by others or not yours (mode {stat.S_IMODE(st.st_mode):o}); "
                "accepted: a file of yours that only you can write (chmod 600)"
            )
        text = os.read(fd, 130)
    finally:
        os.close(fd)
    try:
        secret = bytes.fromhex(text.decode("ascii").strip())
    except (UnicodeDecodeError, ValueError):
        secret = b""
    if len(secret) != 32:
        raise UserError(f"cache key {path}: expected 64 hex digits; remove it (a new key is made on the next run)")
    return secret


def _make_key(path: Path) -> None:
    """A new random key, created 0600 with O_EXCL and linked into place whole: two processes making one
    at once both end up reading the one that won."""
    path.parent.mkdir(mode=0o700, parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".cache.key.", dir=path.parent)  # O_EXCL, mode 0600
    try:
        os.write(fd, os.urandom(32).hex().encode() + b"\n")
        os.fsync(fd)
        os.close(fd)
        fd = -1
        try:
            os.link(tmp, path)  # fails if a key appeared meanwhile: that one is read
        except FileExistsError:
            pass
    finally:
        if fd >= 0:
            os.close(fd)
        os.unlink(tmp)


def secret() -> bytes:
    """The user's cache key (made on first use). Where it can be neither read nor made (a read-only home),
    a key for this process only: nothing on disk verifies then, and every entry is rebuilt once per run."""
    global _secret, _ephemeral
    if _secret is not None:
        return _secret
    path = key_path()
    try:
        root = cache_root().resolve()
        if path.resolve().is_relative_to(root):
            raise UserError(
                f"cache key {path} lies inside the cache folder {root}: whoever can write an entry could read "
                f"it; set {KEY_ENV} to a file outside it"
            )
        try:
            _secret = _read_key(path)
        except FileNotFoundError:
            _make_key(path)
            _secret = _read_key(path)
    except OSError as exc:
        # a warning to act on (the key's folder), not a passing event: every run until it is mended pays for it
        warnings.warn(
            f"cache key {path}: {exc.strerror or exc}; nothing is read from or kept in the cache this run",
            AccelnavWarning,
            stacklevel=2,
        )
        _secret, _ephemeral = os.urandom(32), True
    return _secret


def forget_secret() -> None:
    """Read the key again on next use (tests point :data:`KEY_ENV` elsewhere)."""
    global _secret, _ephemeral
    _secret, _ephemeral = None, False


def tag(name: str, *parts) -> bytes:
    """HMAC-SHA256 under the user's key of an entry's name and its bytes (buffers, hashed in place)."""
    mac = hmac.new(secret(), b"accelnav cache\0" + name.encode() + b"\0", hashlib.sha256)
    for p in parts:
        mac.update(p)
    return mac.digest()


def _note(text: str) -> None:
    """A cache that failed and was worked around: a warning of the run, not an error (see accelnav.progress)."""
    _log.warning(text)


def cache_note(path: Path, reason: str) -> None:
    """The one line a bad entry gets: which file, what was wrong, that it is rebuilt."""
    _note(f"cache entry {path}: {reason}; rebuilt")


@contextmanager
def open_entry(path: Path, limit: int) -> Iterator:
    """An entry's file opened for reading, unbuffered, after checking what it is: FileNotFoundError if there
    is none; ValueError (one line) for a symlink (never followed), a non-regular file (never waited on), or
    one of more than ``limit`` bytes. Yields (file, size)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise ValueError("a symbolic link, not an entry") from None
        raise
    with os.fdopen(fd, "rb", buffering=0) as fh:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError("not a regular file")
        if st.st_size > limit:
            raise ValueError(f"{st.st_size} bytes, more than an entry of its kind can be ({limit})")
        yield fh, st.st_size


def read_into(fh, buf) -> None:
    """Fill ``buf`` (a writable buffer) from ``fh`` by read(), never mapped: a file truncated meanwhile
    gives a short read (ValueError), not SIGBUS."""
    view = memoryview(buf).cast("B")
    got = 0
    while got < len(view):
        n = fh.readinto(view[got:])
        if not n:
            raise ValueError(f"truncated while read ({got} of {len(view)} bytes)")
        got += n


def read_whole(path: Path, limit: int) -> bytearray:
    """Every byte of a regular file of at most ``limit`` bytes (see :func:`open_entry`, :func:`read_into`)."""
    with open_entry(path, limit) as (fh, size):
        buf = bytearray(size)
        read_into(fh, buf)
        if fh.read(1):
            raise ValueError("grew while read")
    return buf


def read_sealed(path: Path, limit: int) -> memoryview:
    """The payload of a sealed entry, verified (a view of the bytes read: nothing copied). FileNotFoundError
    if there is none; ValueError with the reason if it is not an entry this user's key sealed under this
    very name."""
    blob = read_whole(path, limit + HEAD)
    if len(blob) < HEAD or blob[: len(MAGIC)] != MAGIC:
        raise ValueError(f"not a sealed entry ({len(blob)} bytes; truncated or written by something else)")
    view = memoryview(blob)[HEAD:]
    if not hmac.compare_digest(blob[len(MAGIC) : HEAD], tag(path.name, view)):
        raise ValueError("its seal does not verify (edited, damaged, or sealed under another key)")
    return view


def write_sealed(path: Path, *payload) -> bool:
    """Seal ``payload`` (buffers, one after the other) under ``path``'s name and put it in place whole
    (:func:`write_entry`)."""
    return write_entry(path, MAGIC + tag(path.name, *payload), *payload)


def write_entry(path: Path, *parts) -> bool:
    """Put ``parts`` (buffers) at ``path`` whole: a unique O_EXCL temporary name in the same folder, then a
    rename. Best effort: False (said in one line) when the folder cannot take it; False, silently, when the
    key is this process's own (an entry no later run could verify)."""
    secret()
    if _ephemeral:
        return False
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        _note(f"cache entry {path}: not kept ({exc.strerror or exc})")
        return False
    try:
        with os.fdopen(fd, "wb") as fh:
            for part in parts:
                fh.write(part)
        os.chmod(tmp, 0o644)  # nothing secret in it; others holding a shared key may read it
        os.replace(tmp, path)
        return True
    except OSError as exc:
        _note(f"cache entry {path}: not kept ({exc.strerror or exc})")
        try:
            os.unlink(tmp)
        except OSError:
            pass
        return False


def private_copy(folder: Path, name: str, data, mode: int = 0o700) -> Path:
    """Verified bytes of an entry written to a new file ``name`` in a private folder of this user's (a
    TempFolder, mode 0700), never through a planted name (O_EXCL, O_NOFOLLOW). What is run or loaded is
    this copy, never the cache file, which anyone who can write the cache may replace after the check."""
    path = folder / name
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, mode)
    with os.fdopen(fd, "wb") as fh:
        fh.write(data)
    return path


@contextmanager
def entry_lock(path: Path, timeout_s: float = LOCK_TIMEOUT_S) -> Iterator[None]:
    """Hold ``flock`` on ``PATH.lock`` (made if missing, never through a link) while one entry is built.
    A lock that cannot be had (a folder we may not write, a planted link) lets the build go ahead
    unlocked: the entry still appears whole by its rename. One that stays held past ``timeout_s`` is a
    one-line UserError."""
    lock = path.with_name(path.name + ".lock")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
    except OSError:
        yield
        return
    try:
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise UserError(
                        f"cache entry {path}: another process has been building it for {timeout_s:.0f} s; "
                        f"if none is, remove {lock}"
                    ) from None
                time.sleep(0.02)
        yield
    finally:
        os.close(fd)  # releases the lock


def cached(path: Path, build: Callable[[], bytes], *, limit: int, check: Callable[[memoryview], object] | None = None):
    """The verified payload of the entry at ``path`` (a memoryview), else ``build()``'s (bytes), sealed there
    for the next run.

    ``check`` may refuse a verified payload that is still not usable (ValueError): a caller's own shape
    checks. A bad entry is rebuilt with one line on stderr; a missing one silently. Concurrent callers
    needing one entry build it once: the others wait on its lock, then read what it left."""

    def attempt() -> tuple[memoryview | None, str | None]:
        try:
            data = read_sealed(path, limit)
            if check is not None:
                check(data)
            return data, None
        except FileNotFoundError:
            return None, None
        except OSError as exc:
            return None, exc.strerror or str(exc)
        except ValueError as exc:
            return None, str(exc)

    data, bad = attempt()
    if data is not None:
        return data
    with entry_lock(path):
        again, bad_now = attempt()  # built by another process while this one waited for the lock
        if again is not None:
            return again
        bad = bad_now or bad
        if bad:
            cache_note(path, bad)
        data = build()
        if len(data) > limit:
            raise RuntimeError(f"{path.name}: built {len(data)} bytes, more than the {limit} its kind may have")
        write_sealed(path, data)
    return data
