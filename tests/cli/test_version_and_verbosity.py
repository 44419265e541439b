"""accelnav --version, and -q/-v: how much the command says besides its results."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MODELS

import accelnav
from accelnav.cli import main
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
