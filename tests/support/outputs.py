"""Targets for the output rule's tests (accelnav.fileio.output_target), all inside a temporary folder: a FIFO
drained by a thread, a null device node of our own (or, where mknod is not permitted, a file the rule's
predicate is told to treat as a device), and the temporary names a writer would pick."""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

import accelnav.fileio as fileio


class FifoReader:
    """A FIFO at ``path`` whose every byte a thread collects; :meth:`result` ends it (unblocking a reader
    still waiting for a writer that never came) and returns the bytes."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        os.mkfifo(self.path)
        self.data = bytearray()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        with open(self.path, "rb") as fh:  # blocks until a writer opens it
            while chunk := fh.read(1 << 16):
                self.data += chunk

    def result(self, timeout: float = 30.0) -> bytes:
        if self.thread.is_alive():
            try:  # no writer came (a refusal): open and close one so the reader sees the end
                os.close(os.open(self.path, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:
                pass
        self.thread.join(timeout)
        assert not self.thread.is_alive(), f"{self.path}: the reader is still waiting"
        return bytes(self.data)


def fake_device(path: Path, monkeypatch) -> str:
    """A character device at ``path`` that discards what it gets: a null device node made here (root, or
    CAP_MKNOD); else a regular file the rule's own predicate (fileio.written_through) is told is a device.
    Returns which it is."""
    try:
        os.mknod(path, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        return "node"
    except (PermissionError, OSError):
        path.write_bytes(b"")
        real = fileio.written_through
        ino = path.stat().st_ino
        monkeypatch.setattr(fileio, "written_through", lambda p, mode: real(p, mode) or os.stat(p).st_ino == ino)
        return "predicate"


def is_device(path: Path, how: str, ino: int | None = None) -> bool:
    """``path`` is still the fake device ``fake_device`` made (a node: still a character device; a file: the
    same inode, never replaced)."""
    st = os.lstat(path)
    return stat.S_ISCHR(st.st_mode) if how == "node" else st.st_ino == ino


def hidden(folder: Path) -> list[str]:
    """The names a run could have left in ``folder``: hidden entries (temporary files, scratch folders)."""
    return sorted(p.name for p in Path(folder).iterdir() if p.name.startswith("."))
