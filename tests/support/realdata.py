"""A real foot-mounted IMU walk for the tests: gaitmap's example data, fetched from PyPI, never copied here.

Source: the source distribution of gaitmap 2.6.0 on PyPI (MaD-Lab Erlangen,
MIT licence for everything outside its gaitmap_mad/ folder, which we do not
use), folder example_data/: subject 5047, test "normal_20" of the
Fraunhofer / MaD-Lab sensor-position comparison data set (see its
example_data/extract_example_data.py): a healthy subject walks 2 x 20 m with
a turn, a NilsPod IMU (+-16 g) on the lateral side of each shoe at 204.8 Hz,
and a 100 Hz optical motion-capture system tracks heel (FCC), toe (TOE) and
fifth metatarsal (FM5) markers of both feet; the clocks are synchronised.

Files used:

* ``imu_sample.csv``: per foot, acc_x..z in m/s^2 with gravity and gyr_x..z in
  deg/s in gaitmap's foot-aligned sensor frame, 7928 samples (38.7 s);
* ``stride_events_sample.csv``: per stride of each foot, in IMU samples, from
  the motion capture (100 Hz events scaled by 2.048): ``min_vel`` (midstance,
  the stride's start), ``tc`` (toe-off), ``ic`` (heel strike, the next
  stance's start);
* ``mocap_sample.csv``: the markers in mm at 100 Hz, row i at i / 100 s on the
  IMU's clock (the events above were mapped that way by the data set's
  authors).

``orientation_sample.csv`` and ``position_sample.csv`` are not used as
inputs: both were computed from the motion capture markers (the foot's
marker frame at 100 Hz, and the heel marker relative to each stride's start;
extract_example_data.py), so the first is the markers' frame, not the
sensor's, and the second is the same truth as ours, cut per stride.

What the tests make of it (:func:`load_walk`), per foot:

* **level frame**: the IMU's own attitude, as a unit's attitude solution
  would give it: the gyroscope integrated from the start, with roll and pitch
  re-levelled on gravity at the quietest point of each stance (the smallest
  0.05 s mean |gyro| within 0.15 s of the motion capture's midstance, and at
  the start of the recording) and heading kept. The measured acceleration is
  rotated into that frame and gravity subtracted; the two horizontal axes, in
  m/s^2, over the whole recording (standing, 2 x 20 m, the turn, standing);
* **truth**: stride length = horizontal distance of the heel marker (FCC)
  between consecutive midstances, from the motion capture alone (the foot is
  flat and still there, so the exact sample does not matter);
* **reference stances**: for each stance, the run of samples around its
  quietest point whose 0.05 s mean |gyro| stays below 50 deg/s, held within the
  motion capture's heel strike and toe-off: the IMU's gyroscope, which the
  accelerometer-only detector never sees, plays the role of SHOE's gyroscope
  term.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tarfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

GAITMAP = "gaitmap==2.6.0"
SDIST = "gaitmap-2.6.0.tar.gz"
SHA256 = "0312a3fd8c8741afc607cda1b56e6b297416ceb6bc544dfbfaa6af2278478f2c"
MEMBERS = ("imu_sample.csv", "stride_events_sample.csv", "mocap_sample.csv", "position_sample.csv")
RATE = 204.8  # Hz, the IMU
MOCAP_RATE = 100.0  # Hz
G = 9.80665
GYRO_QUIET_DPS = 50.0  # deg/s, reference stance: 0.05 s mean |gyro| below this


def cache_dir() -> Path:
    base = os.environ.get("ACCELNAV_CACHE_DIR")
    root = Path(base) if base else Path.home() / ".cache" / "accelnav"
    return root / "realdata" / "gaitmap-2.6.0"


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _unavailable(why: str):
    """Skip, or fail where the data must be there (CI sets ACCELNAV_REQUIRE_REALDATA=1: it reaches PyPI)."""
    msg = f"real walk data: {why}"
    if os.environ.get("ACCELNAV_REQUIRE_REALDATA") == "1":
        pytest.fail(msg + " (ACCELNAV_REQUIRE_REALDATA=1)")
    pytest.skip(msg)


def fetch() -> Path:
    """The folder holding the example CSVs: downloaded with pip once, checked, extracted; skip if impossible."""
    folder = cache_dir()
    if all((folder / m).is_file() for m in MEMBERS):
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    sdist = folder / SDIST
    if not sdist.is_file():
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:", GAITMAP, "-d", folder]
        try:
            proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.TimeoutExpired) as exc:
            _unavailable(f"cannot run pip download {GAITMAP}: {exc}")
        if proc.returncode != 0 or not sdist.is_file():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            _unavailable(f"pip download {GAITMAP} failed (no network to PyPI?): {tail[0]}")
    digest = _sha256(sdist)
    if digest != SHA256:
        sdist.unlink()
        raise AssertionError(f"{sdist}: sha256 {digest}, expected {SHA256}; removed, run again")
    with tarfile.open(sdist, "r:gz") as tar:
        for m in MEMBERS:
            member = tar.getmember(f"gaitmap-2.6.0/example_data/{m}")
            data = tar.extractfile(member).read()
            tmp = folder / (m + ".part")
            tmp.write_bytes(data)
            tmp.replace(folder / m)
    return folder


@dataclass
class Foot:
    name: str
    t: np.ndarray  # (N,) s
    horizontal: np.ndarray  # (N, 2) m/s^2, level frame, gravity removed
    gyro_dps: np.ndarray  # (N,) |gyro|, deg/s, 0.05 s mean
    midstance: np.ndarray  # (S+1,) IMU samples, from the motion capture
    reference: np.ndarray  # (N,) bool, reference stances
    true_length: np.ndarray  # (S,) m, heel marker between consecutive midstances
    gaitmap_length: np.ndarray  # (S,) m, position_sample.csv (also motion capture), for comparison


def _imu(folder: Path) -> tuple[np.ndarray, dict[tuple[str, str], int]]:
    with open(folder / "imu_sample.csv") as f:
        sensors = f.readline().strip().split(",")
        axes = f.readline().strip().split(",")
    cols = {(s, a): i for i, (s, a) in enumerate(zip(sensors, axes, strict=True)) if i}
    return np.loadtxt(folder / "imu_sample.csv", delimiter=",", skiprows=2), cols


def body_frame(foot: str, folder: Path | None = None) -> tuple[np.ndarray, np.ndarray]:
    """One foot's raw sensor data as recorded: (acc (N, 3) m/s^2 with gravity, gyro (N, 3) rad/s), body frame."""
    raw, cols = _imu(fetch() if folder is None else folder)
    sensor = f"{foot}_sensor"
    acc = raw[:, [cols[(sensor, f"acc_{c}")] for c in "xyz"]]
    return acc, np.deg2rad(raw[:, [cols[(sensor, f"gyr_{c}")] for c in "xyz"]])


def _events(folder: Path) -> list[dict[str, str]]:
    rows = (folder / "stride_events_sample.csv").read_text().strip().splitlines()
    head = rows[0].split(",")
    return [dict(zip(head, r.split(","), strict=True)) for r in rows[1:]]


def _moving_mean(x: np.ndarray, w: int) -> np.ndarray:
    k = np.ones(w) / w
    return np.convolve(np.pad(x, (w // 2, w // 2), mode="edge"), k, mode="valid")


def _tilt_fix(f_world: np.ndarray) -> np.ndarray:
    """The smallest rotation taking the direction f_world onto +z (3x3)."""
    from scipy.spatial.transform import Rotation

    u = f_world / np.linalg.norm(f_world)
    axis = np.cross(u, [0.0, 0.0, 1.0])
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return np.eye(3)
    angle = np.arctan2(s, u[2])
    return Rotation.from_rotvec(axis / s * angle).as_matrix()


def level_frame(acc: np.ndarray, gyr_rad: np.ndarray, resets: list[int], rate: float) -> np.ndarray:
    """(N, 3) acceleration in a level frame, gravity removed: gyro strapdown, re-levelled at ``resets``."""
    from scipy.spatial.transform import Rotation

    n = len(acc)
    ts = 1.0 / rate
    steps = Rotation.from_rotvec(gyr_rad * ts).as_matrix()  # body-frame increments
    reset_at = {int(k): k for k in resets}
    R = np.eye(3)
    out = np.empty((n, 3))
    for k in range(n):
        if k in reset_at:
            lo, hi = max(0, k - 5), min(n, k + 6)
            R = _tilt_fix(R @ acc[lo:hi].mean(axis=0)) @ R
        out[k] = R @ acc[k]
        R = R @ steps[k]
    out[:, 2] -= G
    return out


def load_walk(folder: Path | None = None) -> list[Foot]:
    """Both feet of the walk (see the module docstring)."""
    folder = fetch() if folder is None else folder
    raw, cols = _imu(folder)
    events = _events(folder)
    mocap = np.loadtxt(folder / "mocap_sample.csv", delimiter=",", skiprows=2)
    with open(folder / "mocap_sample.csv") as f:
        markers = f.readline().strip().split(",")
        xyz = f.readline().strip().split(",")
    mcols = {(m, c): i for i, (m, c) in enumerate(zip(markers, xyz, strict=True)) if i}
    gaitmap_pos = _gaitmap_positions(folder)
    n = len(raw)
    t = np.arange(n) / RATE
    feet = []
    for foot in ("left", "right"):
        sensor = f"{foot}_sensor"
        acc = raw[:, [cols[(sensor, f"acc_{c}")] for c in "xyz"]]
        gyr = np.deg2rad(raw[:, [cols[(sensor, f"gyr_{c}")] for c in "xyz"]])
        ev = [e for e in events if e["foot"] == foot]
        mid = np.array([int(float(e["start"])) for e in ev] + [int(float(ev[-1]["end"]))])
        tc = np.array([int(float(e["tc"])) for e in ev])  # toe-off after midstance i
        ic = np.array([int(float(e["ic"])) for e in ev])  # heel strike before midstance i + 1
        wq = int(round(0.05 * RATE)) | 1
        gmean = _moving_mean(np.rad2deg(np.linalg.norm(gyr, axis=1)), wq)
        span = int(round(0.15 * RATE))
        quietest = np.array([m - span + int(np.argmin(gmean[m - span : m + span + 1])) for m in mid])
        world = level_frame(acc, gyr, [0, *quietest.tolist()], RATE)
        ref = np.zeros(n, dtype=bool)
        for i, q in enumerate(quietest):
            lo = ic[i - 1] if i > 0 else 0  # heel strike of this stance
            hi = tc[i] if i < len(tc) else n  # its toe-off
            a = q
            while a - 1 >= lo and gmean[a - 1] < GYRO_QUIET_DPS:
                a -= 1
            b = q
            while b + 1 < hi and gmean[b + 1] < GYRO_QUIET_DPS:
                b += 1
            ref[a : b + 1] = True
        heel = np.stack([mocap[:, mcols[(f"{foot[0].upper()}_FCC", c)]] for c in "xy"], axis=1) / 1000.0
        tm = np.arange(len(heel)) / MOCAP_RATE
        pos = np.stack([np.interp(mid / RATE, tm, heel[:, c]) for c in range(2)], axis=1)
        true_length = np.linalg.norm(np.diff(pos, axis=0), axis=1)
        sids = [int(e["s_id"]) for e in ev]
        gm = np.array([np.linalg.norm(gaitmap_pos[(sensor, s)][:2]) for s in sids])
        feet.append(Foot(foot, t, world[:, :2], gmean, mid, ref, true_length, gm))
    return feet


def _gaitmap_positions(folder: Path) -> dict[tuple[str, int], np.ndarray]:
    """The last sample of each stride in position_sample.csv (x, y, z, m)."""
    last: dict[tuple[str, int], np.ndarray] = {}
    with open(folder / "position_sample.csv") as f:
        f.readline()
        for line in f:
            s, sid, _, x, y, z = line.strip().split(",")
            last[(s, int(sid))] = np.array([float(x), float(y), float(z)])
    return last
