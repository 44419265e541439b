"""The one output rule (accelnav.fileio.output_target and its writer, OutputFile / atomic_output), on the
library: what is replaced, what is written through, what is refused, the temporary names and what a run
that ended leaves behind (issue 30). The commands: tests/cli/test_output_rule_commands.py."""

from __future__ import annotations

import errno
import os
import stat

import numpy as np
import pytest
from support.outputs import FifoReader, fake_device, hidden, is_device
from support.said import listen, notes

import accelnav.fileio as fileio
from accelnav.errors import UserError
from accelnav.estimate.npzout import NpzWriter
from accelnav.fileio import TempFolder, atomic_output, input_limit, output_target
from accelnav.link.logfile import LogWriter, read_log


def _npz(path, n: int = 1000) -> None:
    with NpzWriter(path, {"x": ((n,), np.float64), "s": np.array("text")}) as w:
        w.write("x", 0, np.arange(n, dtype=np.float64))


def _loads(data_or_path) -> None:
    import io

    src = io.BytesIO(data_or_path) if isinstance(data_or_path, bytes) else data_or_path
    with np.load(src) as z:
        np.testing.assert_array_equal(z["x"], np.arange(len(z["x"]), dtype=np.float64))
        assert str(z["s"]) == "text"


def _atomic(path) -> None:
    with atomic_output(path) as fh:
        np.savez(fh, x=np.arange(1000, dtype=np.float64), s=np.array("text"))


@pytest.mark.parametrize("write", [_atomic, _npz], ids=["atomic_output", "NpzWriter"])
def test_a_regular_file_is_replaced_whole_and_nothing_else_stays(tmp_path, write):
    out = tmp_path / "o.npz"
    out.write_bytes(b"old")
    write(out)
    _loads(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.npz"]


@pytest.mark.parametrize("write", [_atomic, _npz], ids=["atomic_output", "NpzWriter"])
def test_a_fifo_is_written_through_and_stays_a_fifo(tmp_path, write):
    fifo = FifoReader(tmp_path / "f.npz")
    write(fifo.path)
    _loads(fifo.result())
    assert stat.S_ISFIFO(os.lstat(fifo.path).st_mode)
    assert hidden(tmp_path) == []


@pytest.mark.parametrize("write", [_atomic, _npz], ids=["atomic_output", "NpzWriter"])
def test_a_symlink_is_followed_its_target_replaced_and_the_link_kept(tmp_path, write):
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / "t.npz"
    target.write_bytes(b"old")
    link = tmp_path / "l.npz"
    link.symlink_to(target)
    write(link)
    assert os.readlink(link) == str(target)
    _loads(target)
    assert hidden(tmp_path) == [] and hidden(tmp_path / "real") == []


@pytest.mark.parametrize("write", [_atomic, _npz], ids=["atomic_output", "NpzWriter"])
def test_a_device_is_written_through_not_replaced(tmp_path, monkeypatch, write):
    dev = tmp_path / "null"
    how = fake_device(dev, monkeypatch)
    ino = os.lstat(dev).st_ino
    assert output_target(dev).kind == fileio.THROUGH
    write(dev)
    assert is_device(dev, how, ino)
    assert hidden(tmp_path) == []


def test_dash_is_standard_output(capfdbinary):
    _npz("-")
    _loads(capfdbinary.readouterr().out)


def test_the_input_itself_is_refused_through_links_too(tmp_path):
    src = tmp_path / "in.npz"
    src.write_bytes(b"recording")
    (tmp_path / "alias.npz").symlink_to(src)
    os.link(src, tmp_path / "hard.npz")
    for name in ("in.npz", "alias.npz", "hard.npz"):
        with pytest.raises(UserError, match=r"is the input .*in\.npz \(the same file\); give another name"):
            atomic_output(tmp_path / name, inputs=[src]).__enter__()
    assert src.read_bytes() == b"recording" and hidden(tmp_path) == []


def test_names_too_long_are_refused_in_one_line(tmp_path):
    with pytest.raises(UserError, match=r"--out: 'a+\.\.\.: a name of 304 bytes; at most \d+ here"):
        output_target(tmp_path / ("a" * 300 + ".npz"))
    with pytest.raises(UserError, match="a name of 304 bytes"):
        NpzWriter(tmp_path / ("a" * 300 + ".npz"), {"x": np.zeros(3)})
    assert list(tmp_path.iterdir()) == []


def test_a_name_near_the_limit_still_gets_a_temporary_name(tmp_path):
    out = tmp_path / ("b" * 250 + ".npz")  # 254 bytes: a temporary name made from it whole would be too long
    _npz(out)
    _loads(out)


def test_missing_folders_are_created_when_the_output_is_written(tmp_path):
    out = tmp_path / "a" / "b" / "o.npz"
    assert output_target(out).kind == fileio.FILE and not (tmp_path / "a").exists()  # the check makes nothing
    _npz(out)
    _loads(out)


@pytest.mark.parametrize("bad", ["dir", "loop", "file-as-folder", "socket"])
def test_what_cannot_be_an_output_is_refused_in_one_line(tmp_path, bad):
    import socket

    p = tmp_path / "x"
    if bad == "dir":
        p.mkdir()
        want = "is a directory"
    elif bad == "loop":
        p.symlink_to(tmp_path / "y")
        (tmp_path / "y").symlink_to(p)
        want = "a symlink loop"
    elif bad == "file-as-folder":
        p.write_text("")
        p = p / "o.npz"
        want = "is not a directory"
    else:
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(p))
        want = "a socket"
    with pytest.raises(UserError, match=want):
        output_target(p)


def test_planted_symlinks_at_every_temporary_name_are_never_followed(tmp_path, monkeypatch):
    """The names a writer picks are exclusive (O_EXCL, O_NOFOLLOW): a link planted at the very name the next
    writer would pick, and at the fixed names of before (OUT.part, .OUT.live.png.part), is passed over."""
    precious = tmp_path / "precious"
    precious.write_bytes(b"keep me")
    calls = []

    def tag() -> str:  # every other name asked for is the planted one
        calls.append(1)
        return "deadbeef" if len(calls) % 2 else f"{len(calls):08x}"

    monkeypatch.setattr(fileio, "_tag", tag)
    pid = os.getpid()
    planted = [
        f".o.npz.{pid}-deadbeef.part",  # OutputFile's temporary file
        f".o.png.live.png.{pid}-deadbeef.part",  # the same for the live plot
        f".accelnav-smooth-{pid}-deadbeef",  # the smoother's and the input's scratch folders
        f".accelnav-input-{pid}-deadbeef",
        "o.npz.part",  # the names of before
        ".o.png.live.png.part",
    ]
    for name in planted:
        (tmp_path / name).symlink_to(precious)
    _npz(tmp_path / "o.npz")  # the first tag is taken: a fresh one
    with TempFolder("smooth", tmp_path) as a, TempFolder("input", tmp_path) as b:
        assert not a.is_symlink() and not b.is_symlink()
        (a / "store.bin").write_bytes(b"scratch")
    from accelnav.link.manifest import Manifest
    from accelnav.model.load import load_model
    from accelnav.plots.live import LivePlot

    model = load_model()
    LivePlot(Manifest.for_model(model), model).save(tmp_path / "o.png.live.png")
    assert precious.read_bytes() == b"keep me"
    assert all((tmp_path / n).is_symlink() for n in planted)
    assert len(calls) == 8  # each writer met its planted name once and took a fresh one
    _loads(tmp_path / "o.npz")
    assert (tmp_path / "o.png.live.png").read_bytes().startswith(b"\x89PNG")


def test_a_leftover_of_a_run_that_ended_is_removed_by_the_next_and_a_live_ones_kept(tmp_path, caplog):
    """A run that ended (its flock gone with it) left a temporary file and a scratch folder: the next writer
    in the folder removes them and says so in one line; a live run's (flock held) are kept."""
    import fcntl

    dead = 2**22 + 17  # a pid number; what decides is the flock, not whether the pid runs
    (tmp_path / f".o.npz.{dead}-0123abcd.part").write_bytes(b"half")
    (tmp_path / f".accelnav-smooth-{dead}-0123abcd").mkdir()
    (tmp_path / f".accelnav-smooth-{dead}-0123abcd" / "store-0.bin").write_bytes(b"x" * 100)
    live = tmp_path / f".other.npz.{os.getpid()}-4567abcd.part"
    live.write_bytes(b"in progress")
    fd = os.open(live, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)
    listen(caplog)
    try:
        _npz(tmp_path / "new.npz")
    finally:
        os.close(fd)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([live.name, "new.npz"])
    (said,) = notes(caplog)  # a note of the library (the command prints it as a line)
    assert f"removed 2 leftover(s) of accelnav runs that ended (pid {dead})" in said


def test_another_live_writer_of_the_same_output_is_refused(tmp_path):
    with atomic_output(tmp_path / "o.npz") as fh:
        fh.write(b"first")
        with pytest.raises(UserError, match=r"another run \(pid \d+\) is writing it now"):
            NpzWriter(tmp_path / "o.npz", {"x": np.zeros(3)})
    assert (tmp_path / "o.npz").read_bytes() == b"first" and hidden(tmp_path) == []


@pytest.mark.parametrize("where", ["write", "fsync"])
def test_a_full_disk_mid_write_is_one_line_and_leaves_nothing(tmp_path, monkeypatch, where):
    def full(*_):
        raise OSError(errno.ENOSPC, "No space left on device")

    if where == "fsync":  # what the file system could not place surfaces at the sync
        monkeypatch.setattr(os, "fsync", full)
    out = tmp_path / "o.csv"
    with pytest.raises(UserError, match=r"--out: .*o\.csv: cannot write: No space left on device"):
        with atomic_output(out, "w") as fh:
            fh.write("x" * 10_000)
            if where == "write":  # as a writer's own write would raise it
                full()
    assert list(tmp_path.iterdir()) == []


def test_the_log_writer_follows_the_rule(tmp_path):
    """The recorder's log: a file appears with its whole header (then grows in place); an existing one is
    replaced only with overwrite; a FIFO is written through; a symlink's target is written."""
    fifo = FifoReader(tmp_path / "f.acnlog")
    with LogWriter(fifo.path, {"k": 1}, fsync_s=None) as log:
        log.append(b"bytes", 1)
    got = fifo.result()
    assert got.startswith(b"ACNLOG1\n") and b"bytes" in got and stat.S_ISFIFO(os.lstat(fifo.path).st_mode)
    target = tmp_path / "t.acnlog"
    (tmp_path / "l.acnlog").symlink_to(target)
    with LogWriter(tmp_path / "l.acnlog", {"k": 2}, fsync_s=None) as log:
        log.append(b"more", 1)
    assert (tmp_path / "l.acnlog").is_symlink() and read_log(target).meta["k"] == 2
    with pytest.raises(FileExistsError):
        LogWriter(target, {"k": 3})
    LogWriter(target, {"k": 4}, overwrite=True).close()
    assert read_log(target).meta["k"] == 4 and hidden(tmp_path) == []
    with pytest.raises(UserError, match="'-' .* not accepted here: a recording goes to a file, a FIFO or a device"):
        LogWriter("-", {})


@pytest.mark.parametrize("value", ["-1", "0", "lots", "1e9"])
def test_max_input_bytes_must_be_a_positive_whole_number(monkeypatch, value):
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", value)
    with pytest.raises(UserError, match=f"ACCELNAV_MAX_INPUT_BYTES: got '{value}'; accepted: a whole number"):
        input_limit()
