"""Every command that writes, by the one output rule (accelnav.fileio.output_target; issue 30): a FIFO and a
device are written through (the FIFO's reader gets the whole output, both stay what they were), a symlink's
target is replaced and the link kept, the input itself as the output is refused in one line before any
work, ``-`` is standard output where the format allows and a one-line refusal where it does not. The rule
on the library: tests/data/test_output_rule.py; crashes, full disks and two writers:
tests/cli/test_output_crashes.py."""

from __future__ import annotations

import csv
import io
import os
import stat
import tomllib

import numpy as np
import pytest
from support.calibrate_cases import nominal_file, perturbed, save_g_csv, tumble_recording
from support.firmware_log import firmware_log
from support.outputs import FifoReader, fake_device, hidden, is_device

from accelnav.cli import main


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs")
    run = d / "run.npz"
    assert main(["sim", "--scenario", "stop_and_go", "--duration", "8", "--out", str(run)]) == 0
    still = d / "still.npz"
    assert main(["sim", "--scenario", "stationary", "--duration", "61", "--out", str(still)]) == 0
    t = np.arange(600) / 100
    a = np.random.default_rng(3).normal(0, 0.05, (600, 2))
    rec = d / "rec.csv"
    np.savetxt(rec, np.column_stack([t, a]), delimiter=",", header="t_s,ax_m_s2,ay_m_s2", comments="", fmt="%.5f")
    nom, model = nominal_file(d)
    tumble, acc = tumble_recording(nom, perturbed(nom, np.random.default_rng(11)), 11)
    cal = save_g_csv(d / "tumble.csv", tumble.t, acc)
    log = firmware_log(d / "fw.acnlog", "states", True, 300)
    return {"RUN": run, "STILL": still, "REC": rec, "TUMBLE": cal, "NOM": model, "LOG": log, "D": d}


# command -> (argv with OUT for the output, the input that --out must not be, the output's format)
COMMANDS = {
    "sim": (["sim", "--duration", "2", "--out", "OUT"], None, "npz"),
    "sim --csv": (["sim", "--duration", "2", "--out", "D/s.npz", "--csv", "OUT"], None, "csv"),
    "filter": (["filter", "RUN", "--out", "OUT"], "RUN", "npz"),
    "smooth": (["smooth", "RUN", "--out", "OUT"], "RUN", "npz"),
    "smooth streamed": (["smooth", "REC", "--memory-budget", "0.001", "--out", "OUT"], "REC", "npz"),
    "smooth --csv": (["smooth", "RUN", "--out", "D/o.npz", "--csv", "OUT"], "RUN", "csv"),
    "smooth --zupt-report": (
        ["smooth", "RUN", "--zupt", "auto", "--zupt-report", "OUT", "--out", "D/z.npz"],
        "RUN",
        "csv",
    ),
    "init": (
        ["init", "--part", "adxl335", "--supply", "3", "--adc-bits", "10", "--rate", "100", "--out", "OUT"],
        None,
        "toml",
    ),
    "fit-bias": (["fit-bias", "STILL", "--out", "OUT"], "STILL", "toml"),
    "calibrate": (["calibrate", "TUMBLE", "--model", "NOM", "--out", "OUT"], "NOM", "toml"),
    "tune": (["tune", "RUN", "--max-evaluations", "12", "--out", "OUT"], "RUN", "toml"),
    "log export csv": (["log", "export", "LOG", "--out", "OUT"], "LOG", "csv"),
    "log export npz": (["log", "export", "LOG", "--out", "OUT"], "LOG", "npz"),
    "log plot": (["log", "plot", "LOG", "--out", "OUT"], "LOG", "png"),
    "record": (["record", "loop://", "--no-commands", "--duration", "0.2", "--out", "OUT"], None, "acnlog"),
}
SUFFIX = {"npz": ".npz", "csv": ".csv", "toml": ".toml", "png": ".png", "acnlog": ".acnlog"}


def _argv(command: str, inputs: dict, out) -> list[str]:
    argv = []
    for a in COMMANDS[command][0]:
        if a == "OUT":
            a = str(out)
        elif a in inputs:
            a = str(inputs[a])
        elif a.startswith("D/"):
            a = str(inputs["D"] / a[2:])
        argv.append(a)
    return argv


def _valid(data: bytes, fmt: str) -> None:
    """The bytes are a whole output of their format."""
    if fmt == "npz":
        with np.load(io.BytesIO(data)) as z:
            assert all(z[k] is not None for k in z.files) and "t" in z.files or "filt_x" in z.files
    elif fmt == "csv":
        rows = list(csv.reader(io.StringIO(data.decode())))  # fields may be quoted (the zupt report's evidence)
        assert len(rows) > 1 and {len(r) for r in rows} == {len(rows[0])}
    elif fmt == "toml":
        assert "sensor" in tomllib.loads(data.decode())
    elif fmt == "png":
        assert data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82")
    else:
        assert data.startswith(b"ACNLOG1\n")


def _run(argv, capsys) -> tuple[int, str, str]:
    status = main(argv)
    got = capsys.readouterr()
    return status, got.out, got.err


@pytest.mark.parametrize("command", COMMANDS)
def test_a_fifo_gets_the_whole_output_and_stays_a_fifo(command, inputs, tmp_path, capsys):
    fmt = COMMANDS[command][2]
    fifo = FifoReader(tmp_path / f"f{SUFFIX[fmt]}")
    status, out, err = _run(_argv(command, inputs, fifo.path), capsys)
    data = fifo.result()
    assert status == 0, err
    _valid(data, fmt)
    assert stat.S_ISFIFO(os.lstat(fifo.path).st_mode)
    assert hidden(tmp_path) == []


@pytest.mark.parametrize("command", COMMANDS)
def test_a_symlink_has_its_target_replaced_and_stays_a_link(command, inputs, tmp_path, capsys):
    fmt = COMMANDS[command][2]
    (tmp_path / "real").mkdir()
    target = tmp_path / "real" / f"t{SUFFIX[fmt]}"
    target.write_bytes(b"old")
    link = tmp_path / f"l{SUFFIX[fmt]}"
    link.symlink_to(target)
    if command in ("record", "init"):  # these replace a file only with --force (init's refusal: below)
        status, _, err = _run([*_argv(command, inputs, link), "--force"], capsys)
    else:
        status, _, err = _run(_argv(command, inputs, link), capsys)
    assert status == 0, err
    assert link.is_symlink() and os.readlink(link) == str(target)
    _valid(target.read_bytes(), fmt)
    assert hidden(tmp_path) == [] and hidden(tmp_path / "real") == []


@pytest.mark.parametrize("command", [c for c, (_, src, _) in COMMANDS.items() if src is not None])
def test_the_input_itself_as_the_output_is_refused_before_any_work(command, inputs, tmp_path, capsys):
    src = inputs[COMMANDS[command][1]]
    before = src.read_bytes()
    status, out, err = _run(_argv(command, inputs, src), capsys)
    assert status == 2 and err.count("\n") == 1, err
    argv = COMMANDS[command][0]
    flag = argv[argv.index("OUT") - 1]
    assert f"{flag}: {src} is the input {src} (the same file); give another name" in err, err
    assert out == ""  # before any work: not a line of it
    assert src.read_bytes() == before


@pytest.mark.parametrize("command", COMMANDS)
def test_a_device_is_written_through_never_replaced(command, inputs, tmp_path, capsys, monkeypatch):
    dev = tmp_path / "null"
    how = fake_device(dev, monkeypatch)
    ino = os.lstat(dev).st_ino
    status, _, err = _run(_argv(command, inputs, dev), capsys)
    if COMMANDS[command][2] in ("png",) or command.startswith("log export"):
        # these choose their format by the name's suffix: a device has none
        assert status == 2 and err.count("\n") == 1 and "accepted: a ." in err, err
    else:
        assert status == 0, err
    assert is_device(dev, how, ino)
    assert hidden(tmp_path) == []


@pytest.mark.parametrize("command", COMMANDS)
def test_dash_is_standard_output_or_refused_in_one_line(command, inputs, capfdbinary):
    status = main(_argv(command, inputs, "-"))
    got = capfdbinary.readouterr()
    fmt = COMMANDS[command][2]
    if command == "record":
        assert status == 2 and got.err.count(b"\n") == 1
        assert b"'-' (standard output) is not accepted here: a recording goes to a file" in got.err
    elif fmt == "png" or command.startswith("log export"):
        assert status == 2 and got.err.count(b"\n") == 1 and b"accepted: a ." in got.err, got.err
    else:
        assert status == 0, got.err[-500:]
        _valid(got.out, fmt)  # the data alone: the command's own lines went to stderr


def test_codegen_writes_into_a_linked_file_and_refuses_a_fifo_as_its_folder(tmp_path, capsys):
    from conftest import MODELS

    model = MODELS / "adxl250_default.toml"
    gen = tmp_path / "gen"
    gen.mkdir()
    elsewhere = tmp_path / "kept.h"
    elsewhere.write_text("old")
    (gen / "accelnav.h").symlink_to(elsewhere)
    assert main(["codegen", str(model), "--out", str(gen)]) == 0
    assert (gen / "accelnav.h").is_symlink() and "#ifndef" in elsewhere.read_text()
    os.mkfifo(tmp_path / "pipe")
    capsys.readouterr()
    assert main(["codegen", str(model), "--out", str(tmp_path / "pipe")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pipe is a FIFO (named pipe); give a directory" in err, err


def test_init_replaces_a_model_only_with_force_and_refuses_empty_axes(tmp_path, capsys):
    out = tmp_path / "m.toml"
    argv = ["init", "--part", "adxl335", "--supply", "3", "--adc-bits", "10", "--rate", "100", "--out", str(out)]
    assert main(argv) == 0
    out.write_text(out.read_text() + "# mine\n")
    capsys.readouterr()
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"accelnav: error: --out: {out} exists; give --force to replace it\n"
    assert out.read_text().endswith("# mine\n")
    assert main([*argv, "--force"]) == 0 and not out.read_text().endswith("# mine\n")
    capsys.readouterr()
    assert main([*argv[:-1], str(tmp_path / "n.toml"), "--axes", ""]) == 2
    err = capsys.readouterr().err
    assert err == "accelnav: error: --axes: got ''; accepted: axis names, comma separated (x,y,z)\n"
    assert main([*argv[:-1], str(tmp_path / "n.toml"), "--axes", "x,,y"]) == 2


@pytest.mark.parametrize("streamed", [False, True])
def test_a_name_too_long_is_one_line_and_a_missing_folder_is_made(streamed, inputs, tmp_path, capsys):
    argv = ["smooth", str(inputs["REC"]), *(["--memory-budget", "0.001"] if streamed else []), "--out"]
    status, out, err = _run([*argv, str(tmp_path / ("a" * 300 + ".npz"))], capsys)
    assert status == 2 and err.count("\n") == 1 and "a name of 304 bytes; at most" in err, err
    status, out, err = _run([*argv, str(tmp_path / "no" / "dir" / "x.npz")], capsys)
    assert status == 0, err
    _valid((tmp_path / "no" / "dir" / "x.npz").read_bytes(), "npz")
    assert hidden(tmp_path / "no" / "dir") == []


@pytest.mark.parametrize("value", ["-1", "0", "many"])
def test_a_bad_input_limit_is_refused_before_any_command_runs(value, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", value)
    status, out, err = _run(["sim", "--duration", "1", "--out", str(tmp_path / "s.npz")], capsys)
    assert status == 2 and out == ""
    assert err == f"accelnav: error: ACCELNAV_MAX_INPUT_BYTES: got '{value}'; accepted: a whole number of bytes > 0\n"


def test_one_output_at_most_goes_to_standard_output(inputs, capsys):
    status, out, err = _run(["smooth", str(inputs["RUN"]), "--out", "-", "--csv", "-"], capsys)
    assert status == 2 and out == ""
    assert err == "accelnav: error: --csv: '-' is already --out's; one output at most goes to standard output\n"


# hil's --out is a folder: its PIL log (pil_BOARD_MODEL_SCENARIO.acnlog) is the file the rule decides on
HIL = ["hil", "--target", "pil", "--duration", "1", "--out"]


def _hil_log(folder, stem: str = "stop_and_go"):
    from accelnav.model.load import load_model

    return folder / f"pil_mps2_an385_{load_model().name}_{stem}.acnlog"


@pytest.fixture
def needs_pil():
    import shutil

    if shutil.which("qemu-system-arm") is None or shutil.which("arm-none-eabi-gcc") is None:
        pytest.skip("PIL on mps2_an385 needs qemu-system-arm and arm-none-eabi-gcc")


def test_hil_pil_log_by_the_output_rule(needs_pil, inputs, tmp_path, capsys, monkeypatch):
    """A FIFO and a device in the log's place are written through (not read back: the result is the run's);
    a symlink's target is replaced and the link kept."""
    (tmp_path / "fifo").mkdir()
    fifo = FifoReader(_hil_log(tmp_path / "fifo"))
    status, out, err = _run([*HIL, str(tmp_path / "fifo")], capsys)
    assert status == 0, err
    _valid(fifo.result(), "acnlog")
    assert stat.S_ISFIFO(os.lstat(fifo.path).st_mode) and "sample rows, bit-identical" in out, out
    dev = _hil_log(tmp_path / "dev")
    dev.parent.mkdir()
    how = fake_device(dev, monkeypatch)
    ino = os.lstat(dev).st_ino
    status, out, err = _run([*HIL, str(tmp_path / "dev")], capsys)
    assert status == 0 and "sample rows, bit-identical" in out, err
    assert is_device(dev, how, ino)
    target = tmp_path / "real.acnlog"
    target.write_bytes(b"old")
    link = _hil_log(tmp_path / "link")
    link.parent.mkdir()
    link.symlink_to(target)
    status, out, err = _run([*HIL, str(tmp_path / "link")], capsys)
    assert status == 0, err
    assert link.is_symlink() and os.readlink(link) == str(target)
    _valid(target.read_bytes(), "acnlog")
    assert all(hidden(tmp_path / d) == [] for d in ("fifo", "dev", "link")) and hidden(tmp_path) == []


def test_hil_refuses_its_input_as_the_pil_log_before_any_work(needs_pil, inputs, tmp_path, capsys):
    src = inputs["LOG"]
    before = src.read_bytes()
    link = _hil_log(tmp_path, src.stem)
    link.symlink_to(src)
    status, out, err = _run(["hil", "--input", str(src), "--target", "pil", "--out", str(tmp_path)], capsys)
    assert status == 2 and err.count("\n") == 1, err
    assert f"--out: {link} is the input {src} (the same file); give another name" in err, err
    assert "SIL:" not in out and src.read_bytes() == before
