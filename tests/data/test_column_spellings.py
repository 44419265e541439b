"""Recordings as other tools write them: ``ax,ay,az`` columns and decimal commas (issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

from accelnav.data.recording import read_recording
from accelnav.errors import UserError
from accelnav.model.load import G0

N = 6000  # 60 s at 100 Hz: as long as the reader asks for


def _signal(k: int) -> tuple[float, float, float]:
    return 0.001 * (k % 7), -0.002 * (k % 5), 1.0 + 0.001 * (k % 3)


@pytest.mark.parametrize("names", [("ax_g", "ay_g", "az_g"), ("a_x_g", "a_y_g", "a_z_g"), ("AX_g", "AY_g", "AZ_g")])
def test_a_and_an_axis_letter_is_an_acceleration_column(tmp_path, names):
    rows = "\n".join(f"{k / 100},{','.join(str(v) for v in _signal(k))}" for k in range(N))
    path = tmp_path / "r.csv"
    path.write_text(f"t,{','.join(names)}\n{rows}\n")
    rec = read_recording(path)
    assert [n.lower() for n in rec.axis_names] == ["x", "y", "z"]
    assert rec.accel[3] == pytest.approx(np.array(_signal(3)) * G0)


def test_plain_ax_columns_take_the_unit_given(tmp_path):
    rows = "\n".join(f"{k / 100},{_signal(k)[0]},{_signal(k)[2]},7" for k in range(N))
    path = tmp_path / "r.csv"
    path.write_text(f"t,ax,az,alt\n{rows}\n")  # "alt" starts with a but is no axis
    rec = read_recording(path, unit="g")
    assert list(rec.axis_names) == ["x", "z"]


@pytest.mark.parametrize("delim", [";", "\t"])
def test_a_decimal_comma_with_semicolons_or_tabs_is_read(tmp_path, delim):
    def num(v: float) -> str:
        return f"{v:.5f}".replace(".", ",")

    rows = "\n".join(delim.join([num(k / 100), *(num(v) for v in _signal(k))]) for k in range(N))
    path = tmp_path / "r.csv"
    path.write_text(delim.join(["t", "acc_x_g", "acc_y_g", "acc_z_g"]) + "\n" + rows + "\n")
    rec = read_recording(path)
    assert rec.t[1] == pytest.approx(0.01)
    assert rec.accel[4] == pytest.approx(np.array(_signal(4)) * G0, abs=1e-5 * G0)


def test_a_bad_cell_in_a_decimal_comma_file_is_named_as_written(tmp_path):
    rows = [f"{k / 100:.2f};{0.001 * (k % 3):.4f}".replace(".", ",") for k in range(N)]
    rows[10] = "0,10;1,2,3"
    path = tmp_path / "r.csv"
    path.write_text("t;acc_x_g\n" + "\n".join(rows) + "\n")
    with pytest.raises(UserError, match=r"line 12, column 'acc_x_g' is not a number \('1,2,3'\)"):
        read_recording(path)


def test_a_decimal_comma_between_commas_is_refused_saying_how_to_convert(tmp_path):
    rows = "\n".join(f"{k / 100:.2f},{0.001 * (k % 3):.4f}".replace(".", ",") for k in range(N))
    path = tmp_path / "r.csv"
    path.write_text(f"t,acc_x_g\n{rows}\n")
    with pytest.raises(UserError) as e:
        read_recording(path)
    msg = str(e.value)
    assert "\n" not in msg and "decimal comma" in msg and "';'" in msg
