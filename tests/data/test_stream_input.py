"""The streamed CSV input (accelnav.data.stream) gives what read_input gives, refuses what it refuses with the
same line, and the CLI streams a CSV over the memory budget to the same run file as the whole path.

Blocks of 7 rows put block boundaries everywhere: between a time step's two samples, inside a gap check."""

from __future__ import annotations

import gzip
import shutil
from collections import namedtuple

import numpy as np
import pytest

from accelnav.cli import main
from accelnav.data.inputs import read_input
from accelnav.data.stream import NotStreamed, open_stream
from accelnav.errors import UserError
from accelnav.model.load import load_model

N = 700  # 7 s at the default model's 100 Hz: a hundred blocks of 7


def _rows(n=N, seed=1, scale=0.3):
    rng = np.random.default_rng(seed)
    return np.arange(n) / 100.0, rng.normal(0, scale, (n, 2))


def _text(header, rows, sep=",", fmt="{:.9g}", end="\n", comma=False):
    lines = [header]
    for row in rows:
        cells = [fmt.format(v) for v in row]
        lines.append(sep.join(c.replace(".", ",") if comma else c for c in cells))
    return end.join(lines) + end


def _codes(n=N, seed=2):
    rng = np.random.default_rng(seed)
    return np.arange(n) / 100.0, rng.integers(400, 620, (n, 2)).astype(float)


Case = namedtuple("Case", "text kw", defaults=({},))


def _cases():
    t, a = _rows()
    tc, codes = _codes()
    both = np.column_stack((t, a))
    return {
        "comma": Case(_text("t_s,acc_x_m_s2,acc_y_m_s2", both)),
        "semicolon decimal comma": Case(_text("t_s;acc_x_g;acc_y_g", both, sep=";", comma=True)),
        "tab": Case(_text("time\tax_g\tay_g", both, sep="\t")),
        "CR line ends": Case(_text("t,acc_x_m_s2,acc_y_m_s2", both, end="\r")),
        "CRLF and comments": Case("# logger v2\n" + _text("t,acc_x_g,acc_y_g", both, end="\r\n")),
        "ms clock": Case(_text("t_ms,acc_x_g,acc_y_g", np.column_stack((t * 1e3, a)))),
        "unsaid ms clock, --time-unit": Case(
            _text("t,acc_x_g,acc_y_g", np.column_stack((t * 1e3, a))), {"time_unit": "ms"}
        ),
        "time last, extra column": Case(
            _text("acc_x_g,temp_c,acc_y_g,t_s", np.column_stack((a[:, 0], a[:, 1], a[:, 1], t))), {}
        ),
        "no time, --rate": Case(_text("acc_x_g,acc_y_g", a), {"rate_hz": 100.0}),
        "--axis reorders": Case(_text("t_s,acc_p_g,acc_q_g", both), {"axes": ["acc_q_g", "acc_p_g"]}),
        "--axis narrows": Case(_text("t_s,acc_x_g,acc_y_g", both), {"axes": ["y"]}),
        "raw counts (analog model)": Case(
            _text("t,ax,ay", np.column_stack((tc, codes)), fmt="{:.6g}"), {"model": load_model(None)}
        ),
        "counts at the rails": Case(
            _text("t,ax,ay", np.column_stack((tc, np.where(codes > 600, 1023, codes))), fmt="{:.6g}"),
            {"model": load_model(None)},
        ),
        "clipped at full scale": Case(_text("t_s,acc_x_g,acc_y_g", np.column_stack((t, np.clip(a * 300, -50, 50))))),
        "mean rate off 100 Hz by 0.5 %": Case(_text("t_s,acc_x_g,acc_y_g", np.column_stack((t * 1.005, a)))),
    }


CASES = _cases()


def _write(tmp_path, case: Case, name="rec.csv", gz=False):
    path = tmp_path / name
    data = case.text.encode()
    path.write_bytes(gzip.compress(data) if gz else data)
    return path


def _same(path, kw, capsys):
    run, model = read_input(path, **kw)
    whole_notes = capsys.readouterr().out
    with open_stream(path, block=7, workdir=path.parent, **kw) as st:
        t, accel, clipped = st(0, st.n)
        parts = [st(s, min(s + 7, st.n)) for s in range(0, st.n, 7)]  # the smoother's reads, block by block
        assert st.n == len(run["t"]) and list(st.axis_names) == [str(a) for a in run["axis_names"]]
        assert [a.name for a in st.model.axes] == [a.name for a in model.axes] and st.model.text == model.text
    assert capsys.readouterr().out == whole_notes  # the same notes, once each
    for got, key in zip((t, accel, clipped), ("t", "accel", "clipped"), strict=True):
        assert np.array_equal(got, run[key]), key  # bit for bit: the same operations on the same numbers
        assert np.array_equal(np.concatenate([p[("t", "accel", "clipped").index(key)] for p in parts]), run[key])
    assert not list(path.parent.glob(".accelnav-input-*"))  # the store is gone


@pytest.mark.parametrize("name", list(CASES))
def test_streamed_equals_whole(tmp_path, capsys, name):
    case = CASES[name]
    _same(_write(tmp_path, case), case.kw, capsys)


def test_streamed_equals_whole_gzip(tmp_path, capsys):
    _same(_write(tmp_path, CASES["comma"], "rec.csv.gz", gz=True), {}, capsys)


def _spoiled(edit, header="t_s,acc_x_g,acc_y_g", n=N, data=None):
    t, a = _rows(n)
    lines = _text(header, np.column_stack((t, a)) if data is None else data).splitlines()
    edit(lines)
    return "\n".join(lines) + "\n"


LAST = N - 3  # a line in the last block of 7 rows, and past the reader's first text piece in the big case


def _set(k, text):
    def edit(lines):
        lines[k] = text

    return edit


REFUSED = {
    "NaN sample in the last block": _spoiled(_set(LAST, "6.96,nan,0.1")),
    "empty cell in the last block": _spoiled(_set(LAST, "6.96,,0.1")),
    "too few fields in the last block": _spoiled(_set(LAST, "6.96,0.1")),
    "time goes back": _spoiled(_set(LAST, "6.00,0.1,0.1")),
    "time not finite": _spoiled(_set(LAST, "inf,0.1,0.1")),
    "a stamp off the grid": _spoiled(_set(LAST, "6.963,0.1,0.1")),
    "a number beyond float64 in m/s^2": _spoiled(_set(LAST, "6.96,1e308,0.1")),
    "model's rate is not the data's": _text("t_s,acc_x_g,acc_y_g", np.column_stack((np.arange(N) / 50.0, _rows()[1]))),
    "a ms clock read as seconds": _text("t,acc_x_g,acc_y_g", np.column_stack((np.arange(N) * 10.0, _rows()[1]))),
    "three axes for two": _text("t_s,ax_g,ay_g,az_g", np.column_stack((*_rows(), _rows()[1][:, 0]))),
    "not an ADC code": _spoiled(_set(LAST, "6.96,512.5,500"), "t,ax,ay", data=np.column_stack(_codes())),
    "one row": "t_s,acc_x_g,acc_y_g\n0,0.1,0.1\n",
    "header only": "t_s,acc_x_g,acc_y_g\n",
}


@pytest.mark.parametrize("name", list(REFUSED))
def test_streamed_refuses_what_whole_refuses(tmp_path, name):
    path = _write(tmp_path, Case(REFUSED[name]))
    model = load_model(None)  # given: a column without a unit is then raw counts
    with pytest.raises(UserError) as whole:
        read_input(path, model)
    with pytest.raises(UserError) as streamed:
        open_stream(path, model, block=7, workdir=tmp_path)
    assert not isinstance(streamed.value, NotStreamed)
    assert str(streamed.value) == str(whole.value)
    print(whole.value)
    assert "\n" not in str(streamed.value)
    assert not list(tmp_path.glob(".accelnav-input-*"))


def test_error_in_the_last_block_of_a_long_file_names_its_line(tmp_path):
    n = 60_000  # several of the parser's text pieces and of the check pass's blocks
    bad = n - 2  # the file's line of that row: the header is line 1
    path = _write(tmp_path, Case(_spoiled(_set(bad, f"{(bad - 1) / 100:.2f},nan,0.1"), n=n)))
    with pytest.raises(UserError, match=rf"sample {bad - 1} \(line {bad + 1}\) is not a number"):
        open_stream(path, block=4096, workdir=tmp_path)


@pytest.mark.parametrize(
    "text,kw",
    [
        # a clock that jitters: stamps placed on the grid by the whole reader
        (
            _text(
                "t_s,acc_x_g,acc_y_g", np.column_stack((np.arange(N) / 100.0 + np.resize([0, 0.004], N), _rows()[1]))
            ),
            {},
        ),
        (_text("t_s,acc_x_g,acc_y_g", np.column_stack(_rows())), {"rate_hz": 100.0}),  # --rate checked on the stamps
        (_spoiled(lambda lines: lines.pop(300)), {"allow_gaps": True}),  # a gap to fill in
    ],
)
def test_what_only_the_whole_reader_does_is_said(tmp_path, text, kw):
    path = _write(tmp_path, Case(text))
    read_input(path, **kw)  # valid
    with pytest.raises(NotStreamed):
        open_stream(path, block=7, workdir=tmp_path, **kw)
    assert not list(tmp_path.glob(".accelnav-input-*"))


def test_a_store_the_disk_cannot_hold_is_refused_in_one_line(tmp_path, monkeypatch, capsys):
    path = _write(tmp_path, CASES["comma"])
    Usage = namedtuple("Usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: Usage(1 << 40, 1 << 40, 1000))
    with pytest.raises(UserError, match=r"need .* GB of disk .* GB are free$"):
        open_stream(path, workdir=tmp_path)
    assert not list(tmp_path.glob(".accelnav-input-*"))
    # the command: refused before anything is read, one line, no traceback
    assert main(["smooth", str(path), "--out", str(tmp_path / "o.npz"), "--memory-budget", "0.01"]) != 0
    err = capsys.readouterr().err.strip()
    assert "GB of disk" in err and "Traceback" not in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o.npz").exists()


def test_cli_streams_a_csv_over_budget_to_the_whole_paths_numbers(tmp_path, capsys):
    n = 250_000  # the whole path takes about 10 s per 1e6 rows here: a quarter keeps the test short
    rng = np.random.default_rng(5)
    path = tmp_path / "big.csv"
    with open(path, "w") as fh:
        fh.write("t_s,acc_x_m_s2,acc_y_m_s2\n")
        np.savetxt(fh, np.column_stack((np.arange(n) / 100.0, rng.normal(0, 0.3, (n, 2)))), delimiter=",", fmt="%.9g")
    small, whole = tmp_path / "small.npz", tmp_path / "whole.npz"
    flags = ["--filter-states", "--full"]  # both stages, so that the filter's numbers are compared too
    assert main(["smooth", str(path), "--out", str(small), "--memory-budget", "16", *flags]) == 0
    said = capsys.readouterr().out
    assert "streamed from the CSV" in said
    assert main(["smooth", str(path), "--out", str(whole), "--memory-budget", "1e6", *flags]) == 0
    said_whole = capsys.readouterr().out
    assert "from the CSV" not in said_whole  # read whole (the smoother may still chunk it)

    def summary(out):  # the run's length and span, and per axis its clipped count and the estimates at the ends
        return [line for line in out.splitlines() if line.startswith("axis ") or line.split()[1:2] == ["samples,"]]

    assert summary(said) == summary(said_whole) and len(summary(said)) == 3
    a, b = np.load(small), np.load(whole)
    for key in ("t", "accel", "clipped", "filt_x", "filt_sd", "smooth_x", "smooth_sd"):
        assert a[key].shape == b[key].shape, key
        np.testing.assert_allclose(a[key], b[key], rtol=1e-12, atol=0, err_msg=key)
    assert not list(tmp_path.glob(".accelnav-*"))


@pytest.mark.parametrize(
    "argv,said",
    [
        (["smooth", "--tune"], "--tune need(s) every sample in memory"),
        (["smooth", "--zupt", "auto", "--memory-budget", "0.01"], "--zupt need(s) every sample in memory"),
    ],
)
def test_what_must_hold_the_input_whole_is_refused_before_reading(tmp_path, monkeypatch, capsys, argv, said):
    path = _write(tmp_path, CASES["comma"])
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", "1000")  # the reader's own limit: it would stop mid-file
    from accelnav.data import recording

    def unread(*a, **k):
        raise AssertionError("the CSV was parsed")

    monkeypatch.setattr(recording, "csv_pieces", unread)
    assert main([argv[0], str(path), *argv[1:], "--out", str(tmp_path / "o.npz")]) != 0
    err = capsys.readouterr().err.strip()
    assert said in err and "ACCELNAV_MAX_INPUT_BYTES" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("where", ["_parse", "_check"])
def test_ctrl_c_removes_the_store(tmp_path, monkeypatch, where):
    from accelnav.data import stream

    real = getattr(stream, where)

    def interrupted(*a, **k):
        real(*a, **k)  # the store is on disk by now
        assert list(tmp_path.glob(".accelnav-input-*/store.bin"))
        raise KeyboardInterrupt

    monkeypatch.setattr(stream, where, interrupted)
    with pytest.raises(KeyboardInterrupt):
        open_stream(_write(tmp_path, CASES["comma"]), workdir=tmp_path)
    assert not list(tmp_path.glob(".accelnav-input-*"))


def test_fixes_and_given_rests_stream_over_the_input_limit_a_csv_mask_does_not(tmp_path, monkeypatch, capsys):
    """Over the input limit and the budget, fixes with rest intervals or an NPZ mask are placed on the streamed
    clock (the run goes on, streamed); a per-sample rest mask given as CSV is read whole: refused in one line."""
    path = _write(tmp_path, CASES["comma"])
    t = _rows(N)[0].tolist()
    fixes, rests, mask_npz, mask_csv = (tmp_path / f for f in ("f.csv", "r.csv", "m.npz", "m.csv"))
    fixes.write_text(f"time_s,axis,position_m,sigma_m\n{t[5]!r},x,0.0,1.0\n{t[-3]!r},y,0.5,1.0\n")
    rests.write_text(f"start_s,end_s\n{t[10]!r},{t[20]!r}\n")
    rest = (np.arange(N) % 50 < 10).astype(np.uint8)
    np.savez(mask_npz, rest=rest)
    mask_csv.write_text("rest\n" + "".join(f"{v}\n" for v in rest))
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", "1000")
    for zupt in (rests, mask_npz):
        out = tmp_path / f"o-{zupt.stem}.npz"
        argv = ["smooth", str(path), "--fixes", str(fixes), "--zupt", str(zupt), "--memory-budget", "0.01"]
        assert main([*argv, "--out", str(out)]) == 0
        said = capsys.readouterr().out
        assert "streamed from the CSV" in said and np.load(out)["zupt"].sum() == (
            22 if zupt == rests else 2 * rest.sum()
        )
    assert main(["smooth", str(path), "--zupt", str(mask_csv), "--out", str(tmp_path / "o.npz")]) != 0
    err = capsys.readouterr().err.strip()
    assert "--zupt need(s) every sample in memory" in err and len(err.splitlines()) == 1
