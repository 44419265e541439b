"""Phone and IMU logs in each app's own layout (tests/support/phone_logs.py: a tilted, turning phone that moves a
known distance): each reader gives the specific force and body rates the phone felt, on the accelerometer's
clock; the device's own orientation is used where the data agree with the format's convention (and its
levelled acceleration recovers the distance), dropped with a note where they do not; what cannot be read is
refused in one line."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
from support import phone_logs as pl
from support.quaternions import about, conj

from accelnav.data.imu import imu_from_frame, read_imu, sniff
from accelnav.errors import UserError
from accelnav.level import G, level_frame, rotate
from accelnav.level.quat import qmul


@pytest.fixture(scope="module")
def phone():
    return pl.phone()


def _unzipped(path, p):
    folder = path / "export"
    folder.mkdir()
    for name, text in pl.sensor_logger_files(p).items():
        (folder / name).write_text(text)
    return folder


# format -> (writer, the format's name in the record's source, has the device's orientation)
WRITERS = {
    "sensor-logger android zip": (lambda d, p: pl.sensor_logger_zip(d / "a.zip", p), "Sensor Logger", True),
    "sensor-logger ios zip": (lambda d, p: pl.sensor_logger_zip(d / "i.zip", p, "ios"), "Sensor Logger", True),
    "sensor-logger folder": (_unzipped, "Sensor Logger", True),
    "phyphox zip": (lambda d, p: pl.phyphox_zip(d / "p.zip", p), "phyphox", False),
    "physics toolbox csv": (lambda d, p: pl.physics_toolbox_csv(d / "pt.csv", p), "Physics Toolbox", False),
    "sensorlog csv": (lambda d, p: pl.sensorlog_csv(d / "sl.csv", p), "SensorLog", True),
    "generic csv": (lambda d, p: pl.generic_csv(d / "g.csv", p), "g.csv", False),
    "generic csv with quaternion": (lambda d, p: pl.generic_csv(d / "q.csv", p, quat=True), "q.csv", True),
}


@pytest.mark.parametrize("fmt", list(WRITERS))
def test_each_reader_gives_what_the_phone_felt(fmt, phone, tmp_path):
    write, name, oriented = WRITERS[fmt]
    path = write(tmp_path, phone)
    assert sniff(path) is not None
    imu = read_imu(path)
    assert name in imu.source
    f, w, _ = pl.truth_at(imu.t)  # every layout starts with the accelerometer's first sample at the truth's 0
    assert abs(imu.t[-1] - phone.t[-1]) < 0.011  # the span every sensor covers, to a sample or two
    assert np.sqrt(np.mean((imu.acc - f) ** 2)) < 0.03  # m/s^2: the noise (0.02) and the format's digits
    assert np.sqrt(np.mean((imu.gyro - w) ** 2)) < 0.005  # rad/s, the gyroscope put on the accelerometer's clock
    assert (imu.quat is not None) == oriented, imu.notes
    assert all("\n" not in n for n in imu.notes)


@pytest.mark.parametrize("fmt", [f for f, (_, _, oriented) in WRITERS.items() if oriented])
def test_the_devices_orientation_levels_it_and_recovers_the_move(fmt, phone, tmp_path):
    imu = read_imu(WRITERS[fmt][0](tmp_path, phone))
    res = level_frame(imu, passes=0)  # the orientation as read, not corrected at rests: the reader's convention alone
    assert res.method == "the recording's own orientation"
    assert any("orientation used" in n for n in imu.notes)
    a_true = np.column_stack([np.interp(imu.t, phone.t, phone.a_level[:, j]) for j in range(3)])
    assert np.sqrt(np.mean((res.acc - a_true) ** 2)) < 0.03
    end = pl.displacement(imu.t, res.acc)[-1]
    np.testing.assert_allclose(end[:2], pl.MOVE, atol=0.03)  # metres, of a 1.1 m move


@pytest.mark.parametrize("fmt", [f for f, (_, _, oriented) in WRITERS.items() if not oriented])
def test_without_an_orientation_the_gyroscope_levels_it(fmt, phone, tmp_path):
    imu = read_imu(WRITERS[fmt][0](tmp_path, phone))
    res = level_frame(imu)
    assert not res.method.startswith("the recording's own orientation")
    # once an attitude filter has settled (its first second), a still phone levels to no acceleration
    still = (imu.t > 1.5) & (imu.t < pl.STILL_S)
    assert np.abs(res.acc[still]).mean() < 0.05


def test_a_data_frame_reads_as_a_generic_csv(phone):
    pd = pytest.importorskip("pandas")
    gyro = np.column_stack([np.interp(phone.t, phone.tg, phone.gyro[:, j]) for j in range(3)])
    frame = pd.DataFrame({"time_ms": phone.t * 1e3, "acc_x_m_s2": phone.f[:, 0], "acc_y_m_s2": phone.f[:, 1],
                          "acc_z_m_s2": phone.f[:, 2], "gyro_x_rad_s": gyro[:, 0], "gyro_y_rad_s": gyro[:, 1],
                          "gyro_z_rad_s": gyro[:, 2]})  # fmt: skip
    imu = imu_from_frame(frame)
    np.testing.assert_allclose(imu.t, phone.t, atol=1e-9)
    np.testing.assert_allclose(imu.acc, phone.f)
    np.testing.assert_allclose(imu.gyro, gyro)
    assert imu.source == "<DataFrame>"


def _turning(n=800, tilt=0.0, rate=0.8):
    """Arrays of a phone turning about the vertical at ``rate`` rad/s, tilted ``tilt`` about its x axis."""
    t = np.arange(n) / 100.0
    yaw, q_tilt = rate * t, about(0, np.full(n, tilt))
    q = qmul(about(2, yaw), q_tilt)
    f = rotate(conj(q), np.tile([0.0, 0.0, G], (n, 1)))
    w = rotate(conj(q), np.tile([0.0, 0.0, rate], (n, 1)))
    return t, f, w, q


def _columns(t, f, w, q):
    cols = {"t": t}
    cols.update({f"a{a}_m_s2": f[:, j] for j, a in enumerate("xyz")})
    cols.update({f"g{a}_rad_s": w[:, j] for j, a in enumerate("xyz")})
    cols.update({f"q{p}": q[:, j] for j, p in enumerate("wxyz")})
    return cols


def test_a_quaternion_the_stated_convention_fits_is_used():
    imu = imu_from_frame(_columns(*_turning(tilt=np.radians(20.0))))
    assert imu.quat is not None
    (said,) = [n for n in imu.notes if "orientation" in n]
    assert "orientation used" in said and "from up" in said and "gyroscope" in said


def test_a_conjugated_quaternion_is_dropped_by_gravity():
    t, f, w, q = _turning(tilt=np.radians(20.0))
    imu = imu_from_frame(_columns(t, f, w, conj(q)))  # level -> device: gravity turned 40 deg off
    assert imu.quat is None
    (said,) = [n for n in imu.notes if "orientation" in n]
    assert "not used" in said and "from up" in said


def test_a_conjugated_quaternion_of_a_flat_phone_is_dropped_by_the_gyroscope():
    """Flat, the conjugate turns gravity up as well: only the turn (the other way round) tells them apart."""
    t, f, w, q = _turning(tilt=0.0)
    imu = imu_from_frame(_columns(t, f, w, conj(q)))
    assert imu.quat is None
    (said,) = [n for n in imu.notes if "orientation" in n]
    assert "not used" in said and "gyroscope" in said


def test_x_y_z_w_order_is_read_by_name(tmp_path):
    t, f, w, q = _turning(tilt=np.radians(20.0))
    cols = _columns(t, f, w, q)
    order = ["t", "qx", "qy", "qz", "qw", "ax_m_s2", "ay_m_s2", "az_m_s2", "gx_rad_s", "gy_rad_s", "gz_rad_s"]
    path = tmp_path / "xyzw.csv"
    path.write_text(",".join(order) + "\n" + "\n".join(",".join(f"{cols[c][k]:.12g}" for c in order)
                                                        for k in range(len(t))) + "\n")  # fmt: skip
    imu = read_imu(path)
    np.testing.assert_allclose(imu.quat, q, atol=1e-9)


def test_ios_sign_is_decided_by_the_orientation_and_said(phone, tmp_path):
    imu = read_imu(pl.sensor_logger_zip(tmp_path / "i.zip", phone, "ios"))
    assert any("CoreMotion's sign" in n for n in imu.notes)
    bare = read_imu(pl.sensor_logger_zip(tmp_path / "j.zip", phone, "ios", drop=("Orientation.csv",)))
    assert any("taken as off" in n for n in bare.notes)
    np.testing.assert_allclose(bare.acc, imu.acc)  # the app's default is CoreMotion's sign: the same numbers


def _refused(path, said: str, **kw):
    with pytest.raises(UserError) as e:
        read_imu(path, **kw)
    assert said in str(e.value), str(e.value)
    assert "\n" not in str(e.value)


def _zip(path, files):
    with zipfile.ZipFile(path, "w") as z:
        for k, v in files.items():
            z.writestr(k, v)
    return path


def test_refusals(phone, tmp_path):
    files = pl.sensor_logger_files(phone)
    no_acc = {k: v for k, v in files.items() if k != "TotalAcceleration.csv"}
    _refused(_zip(tmp_path / "n.zip", no_acc), "no accelerometer")
    ios = pl.sensor_logger_files(phone, "ios")
    _refused(_zip(tmp_path / "u.zip", {k: v for k, v in ios.items() if k != "Gravity.csv"}), "gravity removed")
    late = dict(files)
    late["Gyroscope.csv"] = late["Gyroscope.csv"].replace("1764331", "1764339")  # 8000 s later
    _refused(_zip(tmp_path / "late.zip", late), "never overlap")
    bad = tmp_path / "bad.zip"
    bad.write_bytes(pl.sensor_logger_zip(tmp_path / "ok.zip", phone).read_bytes()[:300])
    _refused(bad, "not a readable zip")


@pytest.mark.parametrize(
    "header, row, said",
    [
        ("t,ax_g,ay_m_s2,az_g,gx_rad_s,gy_rad_s,gz_rad_s", "{t},0,0,1,0,0,0", "mixed units"),
        ("t,ax_g,ay_g,az_g,gx,gy,gz", "{t},0,0,1,0,0,0", "do not say their unit"),
        ("t,ax_g,ay_g,az_g,qw,qx,qy,qz", "{t},0,0,1,0,0,0,0", "zero length"),
        ("t,ax_g,ay_g,az_g,q0,q1,q2,q3", "{t},0,0,1,1,0,0,0", "which part is w"),
        ("t,ax_g,ay_g,az_g,qw,qx,qy", "{t},0,0,1,1,0,0", "a quaternion needs w, x, y, z"),
        ("t,ax_g,ay_g,gx_dps,gy_dps,gz_dps", "{t},0,0,0,0,0", "an IMU needs x, y and z"),
        ("t,lin_acc_x_g,lin_acc_y_g,lin_acc_z_g,gx_dps,gy_dps,gz_dps", "{t},0,0,0,0,0,0", "gravity removed"),
        ("t,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps", "{t},0,0,x1,0,0,0", "az_g"),
    ],
)
def test_generic_refusals(tmp_path, header, row, said):
    path = tmp_path / "r.csv"
    path.write_text(header + "\n" + "\n".join(row.format(t=k / 100) for k in range(50)) + "\n")
    _refused(path, said)


def test_time_going_back_is_refused(tmp_path):
    path = tmp_path / "back.csv"
    rows = [f"{t},0,0,1,0,0,0" for t in (0.0, 0.01, 0.02, 0.015, 0.03)]
    path.write_text("t,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps\n" + "\n".join(rows) + "\n")
    _refused(path, "time goes back")


def test_text_beyond_the_bound_is_refused_before_parsing(phone, tmp_path, monkeypatch):
    path = pl.generic_csv(tmp_path / "g.csv", phone)
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", str(4 * 50_000))  # a quarter: 50 kB of text
    _refused(path, "read whole")
    big = pl.sensor_logger_zip(tmp_path / "a.zip", phone)
    _refused(big, "read whole")
    monkeypatch.setenv("ACCELNAV_MAX_INPUT_BYTES", str(4 * 200_000))  # each file fits, not the three together
    _refused(_unzipped(tmp_path, phone), "read whole")
    _refused(big, "read whole")


def test_binary_data_is_refused(tmp_path):
    path = tmp_path / "nul.csv"
    path.write_bytes(b"t,ax_g,ay_g,az_g,gx_dps,gy_dps,gz_dps\n0,0,0,1,0,0,0\n\0\0\0\n")
    _refused(path, "NUL byte")


def test_plain_recordings_are_not_imu_logs(tmp_path):
    path = tmp_path / "plain.csv"
    path.write_text("t,acc_x_g,acc_y_g\n0,0,0\n0.01,0,0\n")
    assert sniff(path) is None
    assert sniff(tmp_path) is None  # a folder without a logger's files


def test_a_csv_without_gravity_is_read_as_level_axes_and_said(tmp_path):
    """Gyroscope columns beside acceleration that holds no gravity (already levelled): levelling it again would
    be nonsense, so the recording reader reads its axes as they are, and says why."""
    from accelnav.data.recording import read_recording

    path = tmp_path / "levelled.csv"
    rows = [f"{k / 100:.2f},{0.1 * np.sin(k / 10):.5f},0.0,0.0,0,0,0" for k in range(200)]
    path.write_text("t,ax_m_s2,ay_m_s2,az_m_s2,gx_dps,gy_dps,gz_dps\n" + "\n".join(rows) + "\n")
    with pytest.raises(UserError, match="holds no gravity"):
        read_imu(path)
    rec = read_recording(path)
    assert rec.columns == ("ax_m_s2", "ay_m_s2", "az_m_s2")
    assert any("holds no gravity" in n and "not levelled" in n for n in rec.notes)


def test_axis_naming_a_column_of_a_generic_imu_csv_reads_it_plain(phone, tmp_path):
    from accelnav.data.recording import read_recording

    path = pl.generic_csv(tmp_path / "g.csv", phone)
    rec = read_recording(path, axes=["ax_g", "ay_g"])
    assert rec.columns == ("ax_g", "ay_g")
    levelled = read_recording(path, axes=["x", "y"])
    assert levelled.columns == ("x_level", "y_level")


def test_sensorlog_units_are_the_apps(phone, tmp_path):
    path = pl.sensorlog_csv(tmp_path / "s.csv", phone)
    text = path.read_text()
    path.write_text(text.replace("accelerometerAccelerationX(G)", "accelerometerAccelerationX(m/s^2)", 1))
    _refused(path, "accelerometer columns in")


def test_phyphox_acceleration_without_g_alone_is_refused(phone, tmp_path):
    text = pl._csv(['"Time (s)"', '"Linear Acceleration x (m/s^2)"', '"Linear Acceleration y (m/s^2)"',
                    '"Linear Acceleration z (m/s^2)"'], [phone.t, *(phone.f - phone.grav).T], "%.9E")  # fmt: skip
    with zipfile.ZipFile(pl.phyphox_zip(tmp_path / "p.zip", phone)) as z:
        gyro = z.read("Gyroscope.csv").decode()
    path = _zip(tmp_path / "lin.zip", {"Linear Accelerometer.csv": text, "Gyroscope.csv": gyro})
    assert sniff(path) == "phyphox"
    _refused(path, "Acceleration with g")
