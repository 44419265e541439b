"""accelnav --version, and -q/-v: how much the command says besides its results."""

from __future__ import annotations

import logging
import warnings

import numpy as np
import pytest
from conftest import MODELS

import accelnav
from accelnav.cli import main, print_library_lines
from accelnav.errors import AccelnavWarning
from accelnav.progress import Progress


def test_version_is_the_packages(capsys):
    with pytest.raises(SystemExit) as done:
        main(["--version"])
    assert done.value.code == 0
    assert capsys.readouterr().out.strip() == f"accelnav {accelnav.__version__}"
    assert accelnav.__version__[0].isdigit()


@pytest.fixture()
def csv(tmp_path):
    t = np.arange(2000) / 200.0
    rows = ["t,ax,ay"] + [f"{x:.3f},0.01,-0.02" for x in t]
    path = tmp_path / "rec.csv"
    path.write_text("\n".join(rows) + "\n")
    return path


@pytest.mark.parametrize(("flags", "said"), [([], True), (["-q"], False), (["-v"], True)])
def test_quiet_drops_the_notes_but_not_the_results(csv, tmp_path, capsys, flags, said):
    model = str(MODELS / "foot_imu.toml")
    argv = [
        *flags,
        "filter",
        str(csv),
        "--axis",
        "ax",
        "--axis",
        "ay",
        "--model",
        model,
        "--out",
        str(tmp_path / "o.npz"),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert ("columns ax, ay -> model axes x, y" in out) is said
    assert "2000 samples" in out and "wrote" in out  # the results stay
    # progress bars: -v draws them even off a terminal (as here), -q never
    assert Progress("x", 10).enabled is (flags == ["-v"])
    main([])  # back to the default verbosity for the tests that follow
    capsys.readouterr()


def test_quiet_and_verbose_together_are_refused(capsys):
    with pytest.raises(SystemExit) as done:
        main(["-q", "-v", "sim"])
    assert done.value.code == 2 and "not allowed with" in capsys.readouterr().err


def test_the_library_logs_its_notes_and_prints_nothing(csv, capsys, caplog):
    """A notebook's view: the note is a record of the module that speaks, and nothing reaches stdout."""
    caplog.set_level(logging.INFO, logger="accelnav")
    accelnav.read_input(csv, str(MODELS / "foot_imu.toml"), axes=["ax", "ay"])
    assert capsys.readouterr().out == ""
    said = [(r.name, r.levelname, r.getMessage()) for r in caplog.records]
    assert (
        "accelnav.data.inputs",
        "INFO",
        f"{csv}: columns ax, ay -> model axes x, y",
    ) in said, said


@pytest.mark.parametrize("quiet", [False, True])
def test_the_command_prints_notes_warnings_and_library_warnings_as_its_lines(capsys, quiet):
    logger = logging.getLogger("accelnav")
    before = list(logger.handlers), logger.level
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        with print_library_lines(quiet):
            logging.getLogger("accelnav.data.inputs").info("a note")
            logging.getLogger("accelnav.cachefile").warning("cache entry e: rebuilt")
            warnings.warn("cache key k: mend it", AccelnavWarning, stacklevel=1)
    got = capsys.readouterr()
    if quiet:  # -q: only what the user must act on
        assert got.out == "" and got.err == "accelnav: warning: cache key k: mend it\n"
    else:
        assert got.out == "a note\n"
        assert got.err == "accelnav: cache entry e: rebuilt\naccelnav: warning: cache key k: mend it\n"
    assert (list(logger.handlers), logger.level) == before  # the command's handler goes with the command


def test_a_command_run_inside_a_command_prints_each_line_once(capsys):
    with print_library_lines(False), print_library_lines(False):  # the demo runs fit-bias and codegen in itself
        logging.getLogger("accelnav.x").info("once")
    assert capsys.readouterr().out == "once\n"
