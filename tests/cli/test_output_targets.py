"""Outputs of codegen and smooth's side files (issue 21, item 11-12): a wrong target is one line, and
what is written appears whole (fileio.atomic_output, tested in tests/data/test_input_bounds.py)."""

from __future__ import annotations

from conftest import MODELS

from accelnav.cli import main


def test_codegen_out_naming_a_file_is_one_line(tmp_path, capsys):
    out = tmp_path / "build"
    out.write_text("a file where the folder should go")
    assert main(["codegen", str(MODELS / "adxl250_default.toml"), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a file; give a directory" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["build"]


def test_codegen_leaves_no_temporary_beside_its_files(tmp_path, capsys):
    out = tmp_path / "gen"
    assert main(["codegen", str(MODELS / "adxl250_default.toml"), "--out", str(out)]) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == ["accelnav.c", "accelnav.h", "accelnav.json", "acnframe.c", "acnframe.h", "acnframe.json"], names


def test_a_zupt_file_that_is_a_directory_is_named(tmp_path, capsys):
    run = tmp_path / "run.npz"
    assert main(["sim", "--duration", "2", "--out", str(run)]) == 0
    (tmp_path / "rests.npz").mkdir()
    capsys.readouterr()
    argv = ["smooth", str(run), "--zupt", str(tmp_path / "rests.npz"), "--out", str(tmp_path / "o.npz")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "rests.npz: a directory; a file is expected" in err, err
