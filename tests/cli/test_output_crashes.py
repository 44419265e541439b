"""What the output rule promises when things go wrong (issue 30): two runs writing one --out each end whole
and say what is true, a kill -9 at any point of a streamed smooth leaves nothing the next run does not
remove, and a full disk mid-smooth is one line with nothing left behind."""

from __future__ import annotations

import errno
import os
import random
import re
import signal
import sys
import time

import numpy as np
import pytest
from support.outputs import hidden

from accelnav.cli import main


def _csv(path, n: int, seed: int):
    t = np.arange(n) / 100
    a = np.random.default_rng(seed).normal(0, 0.05, (n, 2))
    np.savetxt(path, np.column_stack([t, a]), delimiter=",", header="t_s,ax_m_s2,ay_m_s2", comments="", fmt="%.5f")
    return path


def _spawn(argv: list[str], log) -> int:
    """``accelnav ARGV`` in a forked child (no interpreter start-up: fast rounds), its stdout and stderr
    in ``log``.out / ``log``.err; returns its pid."""
    pid = os.fork()
    if pid == 0:  # the child: its own stdout and stderr (pytest's capture replaced the parent's)
        status = 99
        try:
            for fd, name in ((1, "out"), (2, "err")):
                f = os.open(f"{log}.{name}", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                os.dup2(f, fd)
                os.close(f)
            sys.stdout = open(1, "w", closefd=False)  # noqa: SIM115 (flushed below, the process ends)
            sys.stderr = open(2, "w", closefd=False)  # noqa: SIM115
            status = main(argv)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(status)
    return pid


def _wait(pid: int) -> int:
    return os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])


def _same_run(path, ref) -> bool:
    with np.load(path) as z, np.load(ref) as r:
        return sorted(z.files) == sorted(r.files) and all(np.array_equal(z[k], r[k]) for k in r.files)


@pytest.mark.parametrize(("streamed", "rounds"), [(True, 100), (False, 30)], ids=["streamed", "whole"])
def test_two_runs_writing_one_out_end_whole_and_say_what_is_true(tmp_path, capsys, streamed, rounds):
    """Rounds of two runs (different inputs) at once to one --out: a run that says "wrote" put its
    whole result there; one that met the other writing says so, naming the other's pid; the file is
    always whole and is the result of a run that said "wrote"."""
    budget = ["--memory-budget", "0.001"] if streamed else []
    ins = [_csv(tmp_path / f"in{k}.csv", 150, k) for k in (1, 2)]
    refs = []
    for k, src in enumerate(ins):
        refs.append(tmp_path / f"ref{k}.npz")
        assert main(["smooth", str(src), *budget, "--out", str(refs[-1])]) == 0
    capsys.readouterr()
    out = tmp_path / "w" / "same.npz"
    out.parent.mkdir()
    refused = 0
    # at least ``rounds``, and on until the two runs met (a round is a race: on a loaded machine a short run may
    # finish before the other starts), at most ten times as many
    for r in range(10 * rounds):
        if r >= rounds and refused:
            break
        pids = [_spawn(["smooth", str(src), *budget, "--out", str(out)], tmp_path / f"log{k}") for k, src in
                enumerate(ins)]  # fmt: skip
        codes = [_wait(p) for p in pids]
        said = [((tmp_path / f"log{k}.out").read_text(), (tmp_path / f"log{k}.err").read_text()) for k in (0, 1)]
        wrote = [k for k in (0, 1) if codes[k] == 0]
        assert wrote, (r, codes, said)
        for k in (0, 1):
            if codes[k] == 0:
                assert f"wrote {out}" in said[k][0], said[k]
            else:
                refused += 1
                other = pids[1 - k]
                assert codes[k] == 2 and said[k][1] == (
                    f"accelnav: error: --out: {out}: another run (pid {other}) is writing it now; wait for it to "
                    "finish or give another name\n"
                ), (r, codes, said)
        assert any(_same_run(out, refs[k]) for k in wrote), (r, codes)
        assert hidden(out.parent) == []
    assert refused > 0, "the two runs never overlapped: the rounds tested nothing"


def test_kill_9_anywhere_in_a_streamed_smooth_leaves_nothing_after_the_next_run(tmp_path, capsys):
    big = _csv(tmp_path / "big.csv", 30_000, 1)
    small = _csv(tmp_path / "small.csv", 100, 2)
    rng = random.Random(30)
    left_seen = 0
    for k in range(4):
        d = tmp_path / f"k{k}"
        d.mkdir()
        pid = _spawn(["smooth", str(big), "--memory-budget", "0.01", "--out", str(d / "out.npz")], tmp_path / "kl")
        t0 = time.monotonic()
        while not hidden(d) and time.monotonic() - t0 < 60:
            time.sleep(0.002)
        time.sleep(rng.uniform(0, 0.6))  # a seeded point after its first scratch entry appeared
        os.kill(pid, signal.SIGKILL)
        _wait(pid)
        left = hidden(d)
        left_seen += bool(left)
        capsys.readouterr()
        assert main(["smooth", str(small), "--out", str(d / "next.npz")]) == 0
        said = capsys.readouterr().out
        assert hidden(d) == [] and (d / "out.npz").exists() in (True, False)
        if left:
            lines = [ln for ln in said.splitlines() if "leftover" in ln]
            assert (
                len(lines) == 1
                and f"removed {len(left)} leftover(s) of accelnav runs that ended (pid {pid})" in (lines[0])
            ), said
    assert left_seen >= 2, f"only {left_seen} of the kills left anything: the points missed the run"


def test_a_full_disk_mid_streamed_smooth_is_one_line_and_leaves_nothing(tmp_path, capsys, monkeypatch):
    src = _csv(tmp_path / "in.csv", 3000, 1)
    real = os.pwrite
    calls = []

    def full(fd, data, pos):
        calls.append(1)
        if len(calls) > 20:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data, pos)

    monkeypatch.setattr(os, "pwrite", full)
    out = tmp_path / "o" / "out.npz"
    status = main(["smooth", str(src), "--memory-budget", "0.001", "--out", str(out)])
    err = capsys.readouterr().err
    assert len(calls) > 20, "the smooth never reached the full disk"
    assert status == 2 and err == (
        f"accelnav: error: --out: {out}: cannot write: No space left on device; nothing was left behind\n"
    ), err
    assert re.fullmatch(r"\[\]", str(sorted(p.name for p in out.parent.iterdir()))), list(out.parent.iterdir())
