"""The smoother's gains read back from the cache (fastsmooth.steady_gains, plain_gains with
ACCELNAV_GAIN_CACHE) are sealed, shape-checked before C sees them, and read, not mapped (issue 30).
Before: an edited steady file with its sha256 recomputed was taken silently; gains of the wrong shape
reached the kernel, which read past them; truncating the mapped steady file raised SIGBUS."""

from __future__ import annotations

import hashlib
import io
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from support.cachekey import private_cache
from support.said import listen, warned

from accelnav import cachefile
from accelnav.estimate import fastsmooth as fs
from accelnav.model.design import axis_design
from accelnav.model.edit import with_axis_bias, with_noise


@pytest.fixture(scope="module")
def design(default_model):
    """Settles in about 1 200 samples (tests/estimate/test_steady_gains.py): cheap to compute and to store."""
    ax = default_model.axes[0]
    return axis_design(with_noise(with_axis_bias(default_model, ax.name, ax.c1, ax.c2, 0.5), sigma_eps=0.05), 0)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    folder = private_cache(tmp_path, monkeypatch)
    fs.clear_gain_cache()
    fs.clear_steady_cache()
    yield folder
    fs.clear_gain_cache()
    fs.clear_steady_cache()


def _smooth(d, n=5000):
    z = np.sin(0.3 * np.arange(n) * d.Ts) + np.random.default_rng(5).normal(0, 0.02, n)
    fs.steady_gains(d)  # the rows to the steady state, kept in the cache (or read from it)
    g = fs.plain_gains(d, n)
    return fs.plain_data(d, z, None, g), g


def _forget():
    fs.clear_gain_cache()
    fs.clear_steady_cache()


@pytest.mark.parametrize("forgery", ["sha256 recomputed", "sealed under another key"])
def test_edited_steady_rows_are_refused_and_the_result_is_a_clean_runs(
    cache, design, forgery, tmp_path, monkeypatch, caplog
):
    listen(caplog)
    (xf0, xs0), g0 = _smooth(design)
    (path,) = fs.steady_cache_dir().glob("steady-*.bin")
    st = fs._load_steady(path, fs.steady_key(design))
    rows = st.rows.copy()
    rows[:, 0:2] *= 1.5  # K_r, K_u: what moved the position by 4.3e6 m in the probe
    if forgery == "sha256 recomputed":  # every tag where the file keeps it, made to match with a plain hash
        nt = len(rows)
        head = fs._STEADY_MAGIC + st.key.encode() + nt.to_bytes(8, "little") + (1).to_bytes(8, "little")
        table = hashlib.sha256(rows.tobytes()).digest()
        path.write_bytes(head + hashlib.sha256(head + table).digest() + table + rows.tobytes())
    else:
        with monkeypatch.context() as m:
            m.setenv(cachefile.KEY_ENV, str(tmp_path / "attacker.key"))
            cachefile.forget_secret()
            fs._save_steady(path, fs.SteadyGains(st.key, rows))
        cachefile.forget_secret()
    _forget()
    (xf1, xs1), g1 = _smooth(design)
    assert np.array_equal(xf1, xf0) and np.array_equal(xs1, xs0) and np.array_equal(g1.P_post, g0.P_post)
    (line,) = warned(caplog)
    assert f"cache entry {path}: its seal does not verify" in line and "rebuilt" in line


def test_a_short_run_reads_and_verifies_only_its_blocks(cache, design, monkeypatch, caplog):
    """Rows are sealed in blocks: a run of n samples reads the blocks holding its n rows, exact for it, and a
    longer run reads (and checks) every block."""
    monkeypatch.setattr(fs, "_BLOCK_ROWS", 256)
    full = fs.steady_gains(design)
    nt = len(full.rows)
    assert nt > 3 * 256
    (path,) = fs.steady_cache_dir().glob("steady-*.bin")
    short = fs._load_steady(path, full.key, 300)
    assert len(short.rows) == 512 and not short.settled and np.array_equal(short.rows, full.rows[:512])
    blob = bytearray(path.read_bytes())
    blob[-8:] = np.float64(1e300).tobytes()  # a value in the last block
    path.write_bytes(bytes(blob))
    assert np.array_equal(fs._load_steady(path, full.key, 300).rows, full.rows[:512])
    assert warned(caplog) == []
    assert fs._load_steady(path, full.key) is None  # the whole transient: the edited block is found
    (line,) = warned(caplog)
    assert f"rows block {(nt - 1) // 256} does not verify" in line
    _forget()
    for n in (100, nt + 50):
        ref = fs.plain_gains(design, n, steady=False)
        z = np.random.default_rng(2).normal(0, 0.1, n)
        got = fs.plain_data(design, z, None, fs.plain_gains(design, n))
        assert all(
            np.allclose(a, b, rtol=1e-12, atol=1e-12)
            for a, b in zip(got, fs.plain_data(design, z, None, ref), strict=True)
        )


def _sealed_gains(path, **change):
    """The entry at ``path`` with arrays replaced, sealed with the user's own key (a bug, or a holder of the
    key): only the shape checks stand between it and the kernel."""
    with np.load(io.BytesIO(bytes(cachefile.read_sealed(path, 1 << 30)))) as f:
        arrays = {k: f[k] for k in f.files}
    arrays.update(change)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    assert cachefile.write_sealed(path, buf.getvalue())


N = 900
BAD = {
    "K of one column": {"K": np.zeros((N, 1))},
    "K of 4 rows, not all valid": {"K": np.zeros((4, 4)), "Cs": np.zeros((4, 4))},
    "Cs shorter than K": {"Cs": np.zeros((N - 1, 4))},
    "P of N - 1 rows": {"P_post": np.zeros((N - 1, 10))},
    "float32": {"Ps": np.zeros((N, 10), np.float32)},
    "Fortran order": {"K": np.asfortranarray(np.zeros((N, 4)))},
    "no all_valid": {"all_valid": None},
    "an extra array": {"extra": np.zeros(3)},
    "all_valid of two": {"all_valid": np.array([True, False])},
}


@pytest.mark.parametrize("bad", list(BAD))
def test_gains_of_the_wrong_shape_are_refused_before_c(cache, design, bad, tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("ACCELNAV_GAIN_CACHE", str(tmp_path / "gains"))
    valid = np.ones(N, dtype=bool)
    valid[::5] = False
    z = np.random.default_rng(1).normal(0, 0.1, N)
    ref = fs.plain_data(design, z, valid, fs.plain_gains(design, N, valid))
    (path,) = (tmp_path / "gains").glob("gains-*.npz")
    _sealed_gains(path, **BAD[bad])
    _forget()
    got = fs.plain_gains(design, N, valid)
    for k in ("K", "Cs"):
        assert getattr(got, k).shape == (N, 4)  # what reaches the kernel: the recomputed gains
    assert all(np.array_equal(a, b) for a, b in zip(fs.plain_data(design, z, valid, got), ref, strict=True))
    (line,) = warned(caplog)
    assert f"cache entry {path}:" in line and "rebuilt" in line, line


SCRIPT = """
import os, sys
import numpy as np
from accelnav.estimate import fastsmooth as fs
from accelnav.model.design import axis_design
from accelnav.model.edit import with_axis_bias, with_noise
from accelnav.model.load import load_model
m = load_model()
ax = m.axes[0]
d = axis_design(with_noise(with_axis_bias(m, ax.name, ax.c1, ax.c2, 0.5), sigma_eps=0.05), 0)
first = float(fs.steady_gains(d).rows.sum())
fs.clear_steady_cache()
st = fs.steady_gains(d)  # read back from the file
(path,) = fs.steady_cache_dir().glob("steady-*.bin")
os.truncate(path, 0)  # another tool truncates the file in place while this run holds its rows
print(first == float(st.rows.sum()))
fs.clear_steady_cache()
print(float(fs.steady_gains(d).rows.sum()) == first)  # the emptied file: one line, rebuilt
"""


def test_truncating_the_steady_file_under_a_run_is_no_signal(cache, tmp_path):
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(SCRIPT)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"exit {done.returncode} (SIGBUS is -7): {done.stderr[-2000:]}"
    assert done.stdout.split() == ["True", "True"]
    assert done.stderr.count("\n") == 1 and "truncated while read (0 of" in done.stderr
