"""accelnav demo: the whole chain (warm-up, fit-bias, codegen, SIL/PIL, decode, smooth) on the default model."""

from __future__ import annotations

import shutil

import pytest

from accelnav.cli import main
from accelnav.model.load import load_model


def test_demo_runs_the_whole_chain(tmp_path, capsys):
    status = main(["demo", "--warmup", "900", "--duration", "15", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert status == 0, out
    for step in ("fit-bias", "codegen", "SIL", "decode the telemetry"):
        assert step in out
    if shutil.which("qemu-system-arm") and shutil.which("arm-none-eabi-gcc"):
        assert "bit-identical to SIL" in out
    # what each step left behind
    fitted = load_model(tmp_path / "fitted.toml")
    assert fitted.name.endswith("_fit") or fitted.name == "adxl250_default"
    assert {p.name for p in (tmp_path / "gen").iterdir()} >= {"accelnav.c", "accelnav.h", "accelnav.json"}
    for name in ("position.png", "position_error.png", "report.md"):
        assert (tmp_path / name).stat().st_size > 500, name
    assert not list(tmp_path.glob("fig1*.png"))  # no figure of curves the table does not list
    assert any((tmp_path / "fit").glob("*_fit.png"))
    # the table: smoothing with zero-velocity updates must beat the firmware's filter at the end of the run
    rows = {}  # (axis, estimate) -> |final error|; columns: axis, estimate, rms, final, max |e|
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 5 and parts[0] in ("x", "y"):
            rows[(parts[0], " ".join(parts[1:-3]))] = abs(float(parts[-2]))
    for axis in ("x", "y"):
        assert rows[(axis, "smoother + ZUPT")] < rows[(axis, "firmware filter")], rows


def test_demo_refuses_pil_on_without_emulator(tmp_path, capsys, monkeypatch):
    import accelnav.cli.demo as demo

    monkeypatch.setattr(demo.shutil, "which", lambda name: None)
    assert main(["demo", "--pil", "on", "--out", str(tmp_path)]) == 2
    assert "--pil on" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv,words",
    [
        (["--duration", "-3"], "--duration: got -3 s"),
        (["--warmup", "1e6"], "--warmup: got 1e+06 s"),
        (["--scenario", "moon"], "unknown scenario 'moon'"),
    ],
)
def test_demo_bad_arguments(tmp_path, capsys, argv, words):
    assert main(["demo", *argv, "--pil", "off", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("accelnav: error:") and "Traceback" not in err and words in err, err
    assert not any(tmp_path.iterdir()), "refused before doing any work"
