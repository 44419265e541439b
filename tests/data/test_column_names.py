"""Columns read as the user meant them (issue 33): axes and units by name in any order, a unit the name or
the data contradict refused naming the likely one, and times of every pandas type and epoch unit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from support.said import listen, notes

from accelnav.data.inputs import read_input
from accelnav.data.stream import open_stream
from accelnav.errors import UserError
from accelnav.model.load import DEFAULT_MODEL, G0

N = 3000  # 30 s at the default model's 100 Hz
T = np.arange(N) / 100.0
X = 0.3 * np.sin(T)  # m/s^2: the two axes told apart by their shapes
Y = -0.2 * np.cos(0.5 * T) + 0.05
ADXL202 = DEFAULT_MODEL.parent / "adxl202_duty.toml"  # a +-2 g part

# (time column, its scale from s, x column, y column, the axes' scale from m/s^2, --unit)
SPELLINGS = [
    ("t_ms", 1e3, "acc_x_g", "acc_y_g", 1 / G0, None),
    ("t", 1.0, "ax_m_s2", "ay_m_s2", 1.0, None),
    ("Time (s)", 1.0, "Linear Acceleration x (m/s^2)", "Linear Acceleration y (m/s^2)", 1.0, None),  # phyphox
    ("Time (s)", 1.0, "Acceleration x (m/s^2)", "Acceleration y (m/s^2)", 1.0, None),
    ("seconds_elapsed", 1.0, "x", "y", 1.0, "m/s^2"),  # Sensor Logger
    ("time[ms]", 1e3, "accel_x", "accel_y", 1 / G0, "g"),
    ("t_s", 1.0, "x_accel", "y_accel", 1.0, None),  # accelnav sim --csv
    ("t_us", 1e6, "accX_mg", "accY_mg", 1e3 / G0, None),
]


def _write(path, header, cols, fmt="%.10g"):
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(header), comments="", fmt=fmt)
    return path


def _cases():
    for sp in SPELLINGS:
        for order in itertools.permutations(range(3)):
            yield pytest.param(sp, order, id=f"{sp[2]}-{''.join(map(str, order))}")


@pytest.mark.parametrize(("spelling", "order"), list(_cases()))
def test_axes_and_units_from_names_in_every_column_order(tmp_path, spelling, order):
    tcol, ts, xcol, ycol, scale, unit = spelling
    names, data = [tcol, xcol, ycol], [T * ts, X * scale, Y * scale]
    path = _write(tmp_path / "r.csv", [names[i] for i in order], [data[i] for i in order])
    run, model = read_input(path, unit=unit)
    assert [a.name for a in model.axes] == ["x", "y"]
    assert run["accel"][:, 0] == pytest.approx(X, abs=1e-8) and run["accel"][:, 1] == pytest.approx(Y, abs=1e-8)
    assert run["t"][1] - run["t"][0] == pytest.approx(0.01)
    with open_stream(path, unit=unit, block=700) as st:  # the streamed reader takes the same rules
        t, accel, _ = st(0, st.n)
    assert accel == pytest.approx(run["accel"], abs=1e-12)
    frame = pytest.importorskip("pandas").DataFrame({names[i]: data[i] for i in order})
    accel = read_input(frame, unit=unit)[0]["accel"]  # the numbers themselves, not their text
    assert accel[:, 0] == pytest.approx(X, abs=1e-12) and accel[:, 1] == pytest.approx(Y, abs=1e-12)


def test_sensor_logger_reads_its_z_y_x_columns_by_name_and_its_clock_in_seconds(tmp_path):
    """Sensor Logger writes time (Unix ns), seconds_elapsed, z, y, x; the model here has x and y."""
    ns = 1_727_600_000_000_000_000 + np.round(T * 1e9).astype(np.int64)
    path = tmp_path / "Accelerometer.csv"
    rows = "\n".join(f"{ns[k]},{T[k]:.6f},{9.81:.4f},{Y[k]:.10g},{X[k]:.10g}" for k in range(N))
    path.write_text(f"time,seconds_elapsed,z,y,x\n{rows}\n")
    run, _ = read_input(path, axes=["x", "y"], unit="m/s^2")
    assert run["accel"][:, 0] == pytest.approx(X) and run["accel"][:, 1] == pytest.approx(Y)


def test_a_unit_flag_that_contradicts_a_name_is_refused(tmp_path):
    path = _write(tmp_path / "r.csv", ["t", "acc_x_g", "acc_y_g"], [T, X / G0, Y / G0])
    with pytest.raises(UserError) as e:
        read_input(path, unit="m/s^2")
    assert str(e.value) == (
        f"{path}: --unit m/s^2 contradicts column 'acc_x_g', whose name says g; drop --unit or rename the column"
    )


def _vehicle(seed=2) -> np.ndarray:
    """Accelerations [m/s^2] a car's might be: a few m/s^2, often above 2."""
    rng = np.random.default_rng(seed)
    return 3.0 * np.sin(0.7 * T)[:, None] + 0.05 * rng.standard_normal((N, 2))


@pytest.mark.parametrize("streamed", [False, True])
def test_m_s2_read_as_g_past_the_parts_range_is_refused_naming_m_s2(tmp_path, streamed):
    a = _vehicle()
    path = _write(tmp_path / "r.csv", ["t", "x", "y"], [T, a[:, 0], a[:, 1]])
    with pytest.raises(UserError) as e:
        if streamed:
            open_stream(path, ADXL202, unit="g").close()
        else:
            read_input(path, ADXL202, unit="g")
    msg = str(e.value)
    assert msg.startswith(f"{path}: column 'x' read in g (--unit) puts ") and "\n" not in msg
    assert "beyond the sensor's range +-2 g" in msg and "most likely in m/s^2: give --unit m/s^2" in msg
    run, _ = read_input(path, ADXL202, unit="m/s^2")  # the unit the data say: read
    assert run["accel"][:, 0] == pytest.approx(a[:, 0])


def test_a_level_of_9_8_read_as_g_is_refused_as_m_s2(tmp_path):
    rng = np.random.default_rng(3)
    y = G0 + 0.01 * rng.standard_normal(N)  # a still axis on gravity, in m/s^2
    path = _write(tmp_path / "r.csv", ["t", "x", "y"], [T, 0.01 * rng.standard_normal(N), y])
    with pytest.raises(UserError, match=r"column 'y' read in g \(--unit\) holds 9.80\d g on average.*most likely in "
                       r"m/s\^2: give --unit m/s\^2"):  # fmt: skip
        read_input(path, unit="g")


def test_the_data_stay_out_when_they_cannot_tell(tmp_path):
    """Small level data read in g and a part clipped at its rails in its right unit are not called wrong."""
    path = _write(tmp_path / "small.csv", ["t", "x", "y"], [T, X, Y])
    assert read_input(path, unit="g")[0]["accel"][:, 0] == pytest.approx(X * G0)
    a = np.clip(_vehicle(), -2.0, 2.0)  # in g, a third at the +-2 g rails: clipping, not a unit
    path = _write(tmp_path / "clipped.csv", ["t", "x", "y"], [T, a[:, 0], a[:, 1]])
    run, _ = read_input(path, ADXL202, unit="g")
    assert run["clipped"].mean() > 0.2


# --------------------------------------------------------------------------- times


START = "2024-09-29 08:53:20"


def _times():
    pd = pytest.importorskip("pandas")
    stamps = pd.date_range(START, periods=N, freq="10ms")
    return {
        "datetime64 column": pd.DataFrame({"time": stamps, "acc_x_m_s2": X, "acc_y_m_s2": Y}),
        "datetime64 column not named as time": pd.DataFrame({"when": stamps, "acc_x_m_s2": X, "acc_y_m_s2": Y}),
        "DatetimeIndex": pd.DataFrame({"acc_x_m_s2": X, "acc_y_m_s2": Y}, index=stamps),
        "Timedelta column": pd.DataFrame({"t": pd.to_timedelta(T, unit="s"), "acc_x_m_s2": X, "acc_y_m_s2": Y}),
        "tz-aware column": pd.DataFrame(
            {"time": stamps.tz_localize("Europe/Berlin"), "acc_x_m_s2": X, "acc_y_m_s2": Y}
        ),  # fmt: skip
        "tz-aware index": pd.DataFrame({"acc_x_m_s2": X, "acc_y_m_s2": Y}, index=stamps.tz_localize("US/Pacific")),
    }


@pytest.mark.parametrize(
    "kind",
    ["datetime64 column", "datetime64 column not named as time", "DatetimeIndex", "Timedelta column",
     "tz-aware column", "tz-aware index"],
)  # fmt: skip
def test_each_pandas_time_type_reads_as_seconds(kind, caplog):
    listen(caplog)
    run, _ = read_input(_times()[kind])
    dt = np.diff(run["t"])
    assert dt == pytest.approx(0.01, abs=1e-6) and len(run["t"]) == N
    assert run["accel"][:, 0] == pytest.approx(X)
    said = [line for line in notes(caplog) if "read from its" in line]
    assert len(said) == 1 and ("timedelta64" in said[0] or "since 1970-01-01 UTC" in said[0])


def test_a_tz_aware_time_is_read_in_utc():
    pd = pytest.importorskip("pandas")
    local = pd.date_range(START, periods=N, freq="10ms", tz="Europe/Berlin")  # UTC+2 in September
    run, _ = read_input(pd.DataFrame({"time": local, "acc_x_m_s2": X, "acc_y_m_s2": Y}))
    assert run["t"][0] == pytest.approx(pd.Timestamp(START, tz="UTC").timestamp() - 7200, abs=1e-6)


@pytest.mark.parametrize(("unit", "scale"), [("s", 1), ("ms", 10**3), ("us", 10**6), ("ns", 10**9)])
def test_unix_time_in_each_unit_is_read_from_its_numbers_and_said(tmp_path, caplog, unit, scale):
    listen(caplog)
    start = 1_727_600_000
    # integers, as loggers write them (seconds with their two decimals)
    stamps = [f"{start + k / 100:.2f}" if unit == "s" else start * scale + k * scale // 100 for k in range(N)]
    path = tmp_path / "r.csv"
    rows = "\n".join(f"{stamps[k]},{X[k]:.10g},{Y[k]:.10g}" for k in range(N))
    path.write_text(f"t,acc_x_m_s2,acc_y_m_s2\n{rows}\n")
    run, _ = read_input(path)
    assert run["t"][0] == pytest.approx(start) and np.diff(run["t"]) == pytest.approx(0.01, abs=1e-6)
    words = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}[unit]
    assert f"time column 't' read as Unix time in {words} (first stamp 2024-09-29 08:53:20 UTC" in "\n".join(
        notes(caplog)
    )
    with open_stream(path, block=700) as st:  # the streamed reader decides the same
        assert st(0, st.n)[0] == pytest.approx(run["t"])
        assert st.time_unit == unit


def test_time_unit_ns_is_accepted_for_a_relative_clock(tmp_path):
    path = _write(tmp_path / "r.csv", ["t", "acc_x_m_s2", "acc_y_m_s2"], [np.round(T * 1e9), X, Y], fmt="%.12g")
    run, _ = read_input(path, time_unit="ns")
    assert np.diff(run["t"]) == pytest.approx(0.01)
    with pytest.raises(UserError, match="looks like milliseconds"):  # unsaid and no calendar's: not guessed
        read_input(path)
