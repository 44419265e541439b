"""``log export`` writes what was recorded, as the --out suffix asks (.csv or .npz), or refuses in one line:
a compact log recorded with --manifest (no model text) wrote "0 rows" with exit 0 as CSV, and as NPZ was
told to export to .csv instead."""

from __future__ import annotations

import numpy as np
import pytest
from support.firmware_log import firmware_log

from accelnav.cli import main as cli_main
from accelnav.data.runfile import load_run
from accelnav.model.load import DEFAULT_MODEL

N = 700  # samples sent


def _log(tmp_path, mode: str, with_model: bool):
    """A log of the firmware's telemetry as the recorder writes it (with --model or with --manifest)."""
    return firmware_log(tmp_path / f"{mode}_{int(with_model)}.acnlog", mode, with_model, N)


@pytest.mark.parametrize("mode", ["states", "compact"])
@pytest.mark.parametrize("with_model", [True, False])
def test_export_writes_every_sample_in_the_format_asked(tmp_path, capsys, mode, with_model):
    log = _log(tmp_path, mode, with_model)
    given = [] if with_model else ["--model", str(DEFAULT_MODEL)]
    csv, npz = tmp_path / "x.csv", tmp_path / "x.npz"
    assert cli_main(["log", "export", str(log), "--out", str(csv), *given]) == 0
    assert cli_main(["log", "export", str(log), "--out", str(npz), *given]) == 0
    out = capsys.readouterr().out
    assert f"{csv}: {N} rows" in out and f"{npz}: {N} samples" in out, out
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1], np.arange(N))  # the index column: every sample, in order
    arrays, _ = load_run(npz)
    assert len(arrays["t"]) == N


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_compact_log_without_its_model_is_refused_in_one_line(tmp_path, capsys, suffix):
    log = _log(tmp_path, "compact", False)
    out = tmp_path / f"x{suffix}"
    assert cli_main(["log", "export", str(log), "--out", str(out)]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "give --model" in err and f"its {N} samples" in err, err
    assert not out.exists()


def test_state_log_without_its_model_exports_csv_and_asks_for_it_for_npz(tmp_path, capsys):
    log = _log(tmp_path, "states", False)
    assert cli_main(["log", "export", str(log), "--out", str(tmp_path / "x.csv")]) == 0
    assert cli_main(["log", "export", str(log), "--out", str(tmp_path / "x.npz")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "give --model" in err, err
