"""The C parser of a CSV piece (accelnav.data.csvnum) against the numpy reader it stands in for.

Whatever the C accepts must give the very bits np.loadtxt gives through the reader's own numpy path
(recording._parse_piece); whatever it refuses the numpy path then reads or refuses, so at the file
level the reader with and without the C gives the same arrays and the same messages. Random bytes
never crash it and never make it accept what the numpy path refuses.
"""

from __future__ import annotations

import gzip

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from accelnav.data import csvnum
from accelnav.data import recording as rc
from accelnav.errors import UserError

MOD = csvnum.csv_lib()
pytestmark = pytest.mark.skipif(MOD is None, reason="the CSV kernel is not built (no C compiler): numpy path only")
SETTINGS = settings(max_examples=200, deadline=None, suppress_health_check=list(HealthCheck))


def _numpy(text: str, delim: str, ncols: int, use: list[int]) -> np.ndarray:
    """The reader's numpy path for a piece whose every line has the header's fields."""
    cols = [f"c{j}" for j in range(ncols)]
    head = rc._Header(delim, cols, None, cols, ["g"] * ncols, cols, list(use))
    nums = np.arange(1, text.count("\n") + 2)
    return rc._parse_piece(text, nums, head, "piece")


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _c(text: str, delim: str, ncols: int, use: list[int]):
    return csvnum.parse(MOD, text.encode(), delim, ncols, use)


# plain decimal numbers: everything the C promises to read
DECIMAL = r"[ \t]{0,2}[+-]?([0-9]{1,25}(\.[0-9]{0,25})?|\.[0-9]{1,25})([eE][+-]?[0-9]{1,4})?[ \t]{0,2}"
FORMATS = (repr, "{:.17g}".format, "{:.9g}".format, "{:.3e}".format, "{:.6f}".format, "{:+.20E}".format)


@st.composite
def numbers(draw) -> str:
    if draw(st.booleans()):
        return draw(st.from_regex(DECIMAL, fullmatch=True))
    x = draw(st.floats(allow_nan=False, allow_infinity=False, width=draw(st.sampled_from((32, 64)))))
    return draw(st.sampled_from(FORMATS))(x)


@st.composite
def pieces(draw, cell=numbers):
    """(text, delim, ncols, use): rows of numbers, any wanted columns in any order."""
    delim = draw(st.sampled_from([",", ";", "\t"]))
    ncols = draw(st.integers(2, 5))
    use = draw(st.permutations(range(ncols)))[: draw(st.integers(1, ncols))]
    rows = draw(st.integers(1, 12))
    cells = [[draw(cell()) for _ in range(ncols)] for _ in range(rows)]
    if delim == "\t":  # a tab there is the delimiter, not white space around a number
        cells = [[c.replace("\t", " ") for c in row] for row in cells]
    if delim != ",":  # ';' or tab between fields: a decimal comma is read as a point
        cells = [[c.replace(".", ",") if draw(st.booleans()) else c for c in row] for row in cells]
    return "\n".join(delim.join(row) for row in cells), delim, ncols, use


@SETTINGS
@given(pieces())
def test_plain_decimals_are_read_with_numpys_bits(case):
    text, delim, ncols, use = case
    got = _c(text, delim, ncols, use)
    assert not isinstance(got, csvnum.Refused), (got, text)
    assert _same_bits(got, _numpy(text, delim, ncols, use)), text


@pytest.mark.parametrize(
    "cell",
    [
        "0", "-0", "+0", "-0.0e-5", "0e999999", "1e22", "1e23", "9007199254740992", "9007199254740993",
        "9007199254740993e-3", "123456789012345678901234567890", "0.1", "0.30000000000000004",
        "1.7976931348623157e308", "1.7976931348623159e308", "1e309", "-1e400", "4.9406564584124654e-324",
        "2.4703282292062328e-324", "2.4703282292062327e-324", "2.2250738585072011e-308", "1e-400",
        "123.456e-300", ".5", "5.", "  7\t", "00001.2500", "1" * 300 + "e-300",
        "0." + "0" * 380 + "1", "2.5e+0010", "1E5",
    ],
)  # fmt: skip
def test_edge_numbers_are_read_with_numpys_bits(cell):
    text = f"{cell},1\n2,{cell}"
    got = _c(text, ",", 2, [0, 1])
    assert not isinstance(got, csvnum.Refused), got
    assert _same_bits(got, _numpy(text, ",", 2, [0, 1]))


@pytest.mark.parametrize(
    "line,col",
    [
        ("inf,1", 0), ("1,-Infinity", 1), ("nan,1", 0), ("1,NaN", 1),  # numpy reads them; the reader refuses later
        (",1", 0), ("1, ", 1), ('"1",2', 0), ("1_0,2", 0), ("0x10,2", 0), ("1e,2", 0), ("1e+,2", 0), (".,2", 0),
        ("+-1,2", 0), ("1.5.5,2", 0), ("1 2,3", 0), ("1\v,2", 0), ("\u00a01,2", 0), ("１,2", 0), ("1d5,2", 0),
        ("1" * 401 + ",2", 0),  # longer than the C takes: numpy reads it
    ],
)  # fmt: skip
def test_what_the_c_does_not_read_it_names_and_leaves_to_numpy(line, col):
    got = _c("1,2\n" + line, ",", 2, [0, 1])
    assert got == csvnum.Refused(1, col, "not a plain decimal number")


@pytest.mark.parametrize(
    "text,row",
    [("1,2\n1,2,", 1), ("1,2\n1", 1), ("1,2\n\n3,4", 1), ("1,2\n", 1), ("1,2\n1,2,3", 1), ("1,2,3\n4,5", 0)],
)
def test_a_line_with_other_fields_or_blank_is_refused_by_its_row(text, row):
    got = _c(text, ",", 2, [0, 1])
    assert isinstance(got, csvnum.Refused) and got.row == row and got.col == -1, got


def test_a_field_not_wanted_is_not_read():
    assert _same_bits(_c("x y,1\n\u00e9,2", ",", 2, [1]), np.array([[1.0], [2.0]]))


def test_arguments_that_disagree_are_refused_before_any_read():
    for delim, ncols, use in ((",", 2, [2]), (",", 2, []), (",", 2, [0, 0]), ("\n", 2, [0]), (",;", 2, [0])):
        assert _c("1,2", delim, ncols, use) == csvnum.Refused(-1, -1, "arguments disagree")
    for out in (np.empty((1, 3)), np.empty((1, 2), np.float32), np.empty((1, 4))[:, ::2]):  # not 2 float64 fields
        assert csvnum.parse(MOD, b"1,2", ",", 2, [0, 1], out) == csvnum.Refused(-1, -1, "arguments disagree")
    for rows in (0, 2):  # a table for another number of lines: the C counts them
        got = csvnum.parse(MOD, b"1,2", ",", 2, [0, 1], np.empty((rows, 2)))
        assert got == csvnum.Refused(min(rows, 1), -1, "another number of lines")  # where it stopped
    ffi, lib = MOD.ffi, MOD.lib
    bad = np.empty(2, np.int64)
    out = np.empty(2)
    slot = np.array([0, 5], np.int64)  # a slot beyond the output's columns: nothing is written
    rc_ = lib.acsv_parse(b"1,2", 3, ord(","), 0, 2, ffi.from_buffer("int64_t[]", slot), 2, 1,
                         ffi.from_buffer("double[]", out, require_writable=True),
                         ffi.from_buffer("int64_t[]", bad, require_writable=True))  # fmt: skip
    assert rc_ == csvnum.ARGS


# bytes as hostile as can be: CSV's own characters, more often than chance gives them, and any byte
CSVISH = st.one_of(
    st.binary(max_size=200),
    st.text(alphabet='0123456789.,;eE+-\t \n\rinfaN"#x\x00\u00e9', max_size=200).map(str.encode),
)


@settings(max_examples=1500, deadline=None, suppress_health_check=list(HealthCheck))
@given(CSVISH, st.sampled_from([",", ";", "\t"]), st.integers(1, 4), st.data())
def test_random_bytes_never_crash_and_what_is_accepted_numpy_reads_alike(buf, delim, ncols, data):
    use = data.draw(st.permutations(range(ncols)))[: data.draw(st.integers(1, ncols))]
    got = csvnum.parse(MOD, buf, delim, ncols, use)
    if isinstance(got, csvnum.Refused):
        assert -1 <= got.row <= buf.count(b"\n") + 1 and -1 <= got.col < ncols
        return
    assert got.shape == (buf.count(b"\n") + 1, len(use))
    try:  # a piece the reader could hand over: UTF-8, no NUL, no carriage return (already a newline)
        text = buf.decode()
    except UnicodeDecodeError:
        return
    if "\0" in text or "\r" in text or "#" in text:
        return
    assert _same_bits(got, _numpy(text, delim, ncols, use)), buf


# ---- the reader with and without the C: the same arrays, lines and messages for whole files ----


def _read(path, monkeypatch, with_c: bool):
    used = []
    real = csvnum.parse

    def spy(*a):
        got = real(*a)
        used.append(not isinstance(got, csvnum.Refused))
        return got

    monkeypatch.setattr(csvnum, "parse", spy)
    monkeypatch.setattr(csvnum, "csv_lib", (lambda: MOD) if with_c else (lambda: None))
    try:
        pieces = list(rc.csv_pieces(path, None, None, None, None, path.suffix == ".gz", "g"))
    except UserError as exc:
        return str(exc), used
    table = np.concatenate([p[1] for p in pieces])
    return (table, np.concatenate([p[2] for p in pieces])), used


def _both(path, monkeypatch):
    c, used = _read(path, monkeypatch, True)
    numpy_, _ = _read(path, monkeypatch, False)
    if isinstance(c, str) or isinstance(numpy_, str):
        assert c == numpy_
    else:
        assert _same_bits(c[0], numpy_[0]) and np.array_equal(c[1], numpy_[1])
    return c, used


def _body(n: int, rng, delim=",", end="\n") -> str:
    t = np.arange(n) / 100
    a = rng.normal(0, 3, (n, 2))
    return end.join(f"{float(x)!r}{delim}{y:.17g}{delim}{z:.9g}" for x, y, z in zip(t, a[:, 0], a[:, 1], strict=True))


def _deep(body: str, end: str) -> str:
    """``body`` with the line end two thirds in (a later piece than the header's) replaced by ``end``."""
    k = body.index("\n", len(body) * 2 // 3)
    return body[:k] + end + body[k + 1 :]


@pytest.mark.parametrize(
    "name,make",
    [
        ("plain", lambda b: "t_s,acc_x_g,acc_y_g\n" + b + "\n"),
        ("crlf", lambda b: ("t_s,acc_x_g,acc_y_g\n" + b + "\n").replace("\n", "\r\n")),
        ("lone cr", lambda b: ("t_s,acc_x_g,acc_y_g\n" + b).replace("\n", "\r")),
        ("no final newline", lambda b: "t_s,acc_x_g,acc_y_g\n" + b),
        ("blank lines at the end", lambda b: "t_s,acc_x_g,acc_y_g\n" + b + "\n\n\n"),
        ("a bom and a comment before the header", lambda b: "\ufeff# rig 3\nt_s,acc_x_g,acc_y_g\n" + b + "\n"),
        ("columns in another order", lambda b: "acc_y_g,t_s,acc_x_g\n" + b + "\n"),
        ("a column not wanted", lambda b: "t_s,note,acc_y_g\n" + b + "\n"),
        ("semicolons and decimal commas", lambda b: "t_s;acc_x_g;acc_y_g\n" + b.replace(",", ";").replace(".", ",")),
        ("tabs", lambda b: "t_s\tacc_x_g\tacc_y_g\n" + b.replace(",", "\t")),
        ("spaces around", lambda b: "t_s,acc_x_g,acc_y_g\n" + b.replace(",", " , ")),
        ("a trailing delimiter deep in", lambda b: "t_s,acc_x_g,acc_y_g\n" + _deep(b, ",\n")),
        ("an empty field deep in", lambda b: "t_s,acc_x_g,acc_y_g\n" + _deep(b, "\n1e9,,1\n")),
        ("inf deep in", lambda b: "t_s,acc_x_g,acc_y_g\n" + _deep(b, "\n1e9,inf,1\n")),
        ("a blank line deep in", lambda b: "t_s,acc_x_g,acc_y_g\n" + _deep(b, "\n \n")),
        ("an empty line deep in", lambda b: "t_s,acc_x_g,acc_y_g\n" + _deep(b, "\n\n")),
    ],
)  # fmt: skip
@pytest.mark.parametrize("gz", [False, True])
def test_the_reader_gives_the_same_with_and_without_the_c(tmp_path, monkeypatch, name, make, gz):
    text = make(_body(30_000, np.random.default_rng(len(name))))  # about 1.3 MB: several pieces
    path = tmp_path / ("r.csv.gz" if gz else "r.csv")
    path.write_bytes(gzip.compress(text.encode()) if gz else text.encode())
    got, used = _both(path, monkeypatch)
    assert any(used), "the C read no piece: the comparison says nothing"


def test_lines_longer_than_a_piece_and_very_long_numbers(tmp_path, monkeypatch):
    monkeypatch.setattr(rc, "CHUNK_CHARS", 512)  # each line below is longer than a piece
    long = "0." + "0" * 300 + "123456789012345678901234567890"
    lines = [f"{k / 100!r},{long}{k},{'-' if k % 2 else ''}{k}e-{k % 330}" for k in range(300)]
    path = tmp_path / "long.csv"
    path.write_text("t_s,acc_x_g,acc_y_g\n" + "\n".join(lines) + "\n")
    got, used = _both(path, monkeypatch)
    assert sum(used) > 100 and got[0].shape == (300, 3)
