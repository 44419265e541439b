"""Structure-aware fuzz of the recording readers (CSV, gzip CSV, NPZ: accelnav.data.recording).

Inputs start as valid recordings and are damaged where the reader makes decisions: cells, rows,
header names and units, delimiters, line endings, comments, encodings, gzip wrapping; for NPZ the
arrays' keys, dtypes, shapes and values, then the zip bytes themselves. Property: the reader
returns a recording no longer than the file's rows, or refuses with UserError in one line; no
other exception. The seed is random per run and printed; ACCELNAV_FUZZ_SEED=N reruns one exactly.
"""

from __future__ import annotations

import gzip
import io
import os
import random
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, seed, settings
from hypothesis import strategies as st

from accelnav.data.recording import read_recording
from accelnav.errors import UserError
from accelnav.model.load import DEFAULT_MODEL

SEED = int(os.environ.get("ACCELNAV_FUZZ_SEED") or random.SystemRandom().randrange(2**32))
FUZZ = settings(
    max_examples=int(os.environ.get("ACCELNAV_FUZZ_EXAMPLES", "600")),
    derandomize=False,
    database=None,
    deadline=None,
    phases=(Phase.explicit, Phase.generate),  # no shrinking: the seed and the example are printed at once
    suppress_health_check=list(HealthCheck),
)
TMP = Path(tempfile.mkdtemp(prefix="acn-readerfuzz-"))
ROWS = 40


@pytest.fixture(scope="module", autouse=True)
def _say_seed():
    print(f"\nrecording reader fuzz: seed {SEED} (rerun: ACCELNAV_FUZZ_SEED={SEED})")


def _read(path: Path, kw: dict):
    try:
        return read_recording(path, **kw)
    except UserError as exc:
        msg = str(exc)
        assert msg and "\n" not in msg and len(msg) < 2000, msg[:300]
        return None


# ---- CSV --------------------------------------------------------------------------------------

CELLS = st.sampled_from(
    ["", " ", "nan", "inf", "-inf", "1e308", "1e-400", "-0", "abc", "1,5", " 3 ", "0x10", "1_0", "9" * 400, '"1"', "#"]
) | st.floats(allow_nan=True, allow_infinity=True).map(repr)
NAMES = st.sampled_from(
    ["t", "t_s", "time_ms", "timestamp_us", "acc_x_g", "acc_y_mg", "accel_z_m_s2", "acc_x_g", "acc", "x", "", "ß", "1"]
) | st.text(max_size=6)
KW = st.fixed_dictionaries(
    {},
    optional={
        "rate_hz": st.sampled_from([100.0, 0.0, -1.0, float("nan"), float("inf"), 1e-300, 1e300]),
        "axes": st.lists(st.sampled_from(["x", "y", "acc_x_g", "z", "", "t"]), min_size=1, max_size=3),
        "unit": st.sampled_from(["g", "mg", "m/s^2", "furlong", ""]),
        "time_column": st.sampled_from(["t_s", "nope", ""]),
        "allow_gaps": st.booleans(),
    },
)
CSV_OP = st.one_of(
    st.tuples(st.just("cell"), st.integers(0, 10**6), st.integers(0, 10), CELLS),
    st.tuples(st.just("name"), st.integers(0, 10), NAMES),
    st.tuples(st.just("drop_row"), st.integers(0, 10**6)),
    st.tuples(st.just("repeat_row"), st.integers(0, 10**6)),
    st.tuples(st.just("swap_rows"), st.integers(0, 10**6), st.integers(0, 10**6)),
    st.tuples(st.just("extra_cell"), st.integers(0, 10**6)),
    st.tuples(st.just("comment"), st.integers(0, 10**6), st.text(max_size=10)),
    st.tuples(st.just("blank"), st.integers(0, 10**6)),
)
TEXT_OP = st.sampled_from(
    ["none", "crlf", "cr", "semicolon", "tab", "bom", "nul", "truncate", "latin1", "gzip", "gz_cut"]
)


def _csv(ops, text_op: str, cut: int) -> bytes:
    rng = np.random.default_rng(0)
    header = ["t_s", "acc_x_g", "acc_y_g"]
    rows = [
        [f"{k / 100:.2f}", f"{1e-3 * rng.standard_normal():.6f}", f"{1 + 1e-3 * rng.standard_normal():.6f}"]
        for k in range(ROWS)
    ]
    for op in ops:
        kind = op[0]
        if kind == "cell" and rows:
            r = rows[op[1] % len(rows)]
            r[op[2] % len(r)] = op[3]
        elif kind == "name":
            header[op[1] % len(header)] = op[2]
        elif kind == "drop_row" and rows:
            del rows[op[1] % len(rows)]
        elif kind == "repeat_row" and rows:
            i = op[1] % len(rows)
            rows.insert(i, list(rows[i]))
        elif kind == "swap_rows" and rows:
            i, j = op[1] % len(rows), op[2] % len(rows)
            rows[i], rows[j] = rows[j], rows[i]
        elif kind == "extra_cell" and rows:
            rows[op[1] % len(rows)].append("1")
        elif kind == "comment":
            rows.insert(op[1] % (len(rows) + 1), ["#" + op[2]])
        elif kind == "blank":
            rows.insert(op[1] % (len(rows) + 1), [""])
    delim = {"semicolon": ";", "tab": "\t"}.get(text_op, ",")
    text = "\n".join(delim.join(r) for r in [header, *rows]) + "\n"
    if text_op == "crlf":
        text = text.replace("\n", "\r\n")
    elif text_op == "cr":
        text = text.replace("\n", "\r")
    elif text_op == "nul":
        text = text[: cut % len(text)] + "\0" + text[cut % len(text) :]
    data = text.encode("utf-8", "surrogatepass")
    if text_op == "bom":
        data = b"\xef\xbb\xbf" + data
    elif text_op == "truncate":
        data = data[: cut % (len(data) + 1)]
    elif text_op == "latin1":
        data = data.replace(b"t", b"\xe9", 1)
    elif text_op in ("gzip", "gz_cut"):
        data = gzip.compress(data, mtime=0)
        if text_op == "gz_cut":
            data = data[: cut % len(data)]
    return data


@seed(SEED)
@FUZZ
@given(ops=st.lists(CSV_OP, max_size=10), text_op=TEXT_OP, cut=st.integers(0, 10**6), kw=KW)
def test_csv_reader_takes_damaged_files(ops, text_op, cut, kw):
    path = TMP / "fuzz.csv"
    data = _csv(ops, text_op, cut)
    path.write_bytes(data)
    rec = _read(path, kw)
    if rec is not None:
        assert rec.n <= ROWS + len(ops)
        assert rec.accel.shape[0] == rec.n and np.isfinite(rec.t).all()


# ---- NPZ --------------------------------------------------------------------------------------

KEYS = ["t", "accel", "axis_names", "model_toml", "clipped", "rate_hz", "unit"]
VALUES = st.one_of(
    st.sampled_from(
        ["2d_float", "1d_float", "3d", "empty", "scalar", "int", "float32", "complex", "bool", "str", "big"]
    ),
)
NPZ_OP = st.one_of(
    st.tuples(st.just("drop"), st.sampled_from(KEYS)),
    st.tuples(st.just("set"), st.sampled_from(KEYS), VALUES),
    st.tuples(st.just("transpose"), st.sampled_from(KEYS)),
    st.tuples(st.just("poke"), st.sampled_from(KEYS), st.integers(0, 10**6), CELLS),
)
ZIP_OP = st.one_of(
    st.just(("none",)),
    st.tuples(st.just("flip"), st.integers(0, 10**7)),
    st.tuples(st.just("truncate"), st.integers(0, 10**7)),
)


def _value(kind: str, n: int) -> np.ndarray:
    rng = np.random.default_rng(1)
    return {
        "2d_float": rng.standard_normal((n, 2)),
        "1d_float": np.arange(n) / 100.0,
        "3d": np.zeros((n, 2, 2)),
        "empty": np.zeros((0,)),
        "scalar": np.array(3.5),
        "int": np.arange(n, dtype=np.int64),
        "float32": np.arange(n, dtype=np.float32) / 100,
        "complex": np.zeros(n, complex),
        "bool": np.ones((n, 2), bool),
        "str": np.array(["a"] * n),
        "big": np.zeros((n, 40)),
    }[kind]


def _npz(ops, zip_op) -> bytes:
    n = ROWS
    arrays = {
        "t": np.arange(n) / 100.0,
        "accel": np.random.default_rng(2).standard_normal((n, 2)) * 1e-2,
        "axis_names": np.array(["x", "y"]),
        "model_toml": np.array(DEFAULT_MODEL.read_text()),
        "clipped": np.zeros((n, 2), bool),
    }
    for op in ops:
        if op[0] == "drop":
            arrays.pop(op[1], None)
        elif op[0] == "set":
            arrays[op[1]] = _value(op[2], n)
        elif op[0] == "transpose" and op[1] in arrays:
            arrays[op[1]] = np.asarray(arrays[op[1]]).T
        elif op[0] == "poke" and op[1] in arrays:
            a = np.array(arrays[op[1]])
            if a.size:
                try:
                    a.flat[op[2] % a.size] = op[3]
                except (ValueError, TypeError, OverflowError):
                    continue  # not a value of this array's type: the file keeps the old one
                arrays[op[1]] = a
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    data = bytearray(buf.getvalue())
    if zip_op[0] == "flip" and data:
        data[zip_op[1] % len(data)] ^= 1 << (zip_op[1] % 8)
    elif zip_op[0] == "truncate":
        del data[max(2, zip_op[1] % (len(data) + 1)) :]  # keep "PK": still taken for an NPZ
    return bytes(data)


@seed(SEED)
@FUZZ
@given(ops=st.lists(NPZ_OP, max_size=6), zip_op=ZIP_OP, kw=KW)
def test_npz_reader_takes_damaged_files(ops, zip_op, kw):
    path = TMP / "fuzz.npz"
    path.write_bytes(_npz(ops, zip_op))
    kw.pop("time_column", None)
    rec = _read(path, kw)
    if rec is not None:
        assert rec.n <= ROWS * 40 and rec.accel.shape[0] == rec.n
