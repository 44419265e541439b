"""``accelnav level``: a phone or IMU log (body frame, gravity in) into the level-frame recording ``smooth`` reads.

The log is read by :func:`accelnav.data.imu.read_imu` (Sensor Logger, phyphox, Physics Toolbox, SensorLog, a
generic IMU CSV) and levelled by :func:`accelnav.level.level_frame`: its own orientation where the data agree
with the format's convention, else Fusion's AHRS on its gyroscope. ``smooth``, ``filter``, ``tune`` and
``fit-bias`` take such a log directly and level it the same way; this command keeps the levelled recording.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser(
        "level",
        help="level a phone or IMU log (body frame, gravity in) into a level-frame recording smooth reads",
        description="Read a phone logger's export (Sensor Logger zip or folder, phyphox, Physics Toolbox, SensorLog) "
        "or a CSV with acceleration and gyroscope or quaternion columns, level it (x, y horizontal, x along the "
        "device's first heading, z up, gravity removed) and write t, x_accel, y_accel, z_accel in m/s^2.",
    )
    p.add_argument("log", type=Path, help="the IMU log: a CSV, or a Sensor Logger / phyphox zip or folder")
    p.add_argument("--out", type=Path, required=True, metavar="CSV", help="the level-frame recording to write (CSV)")
    p.add_argument(
        "--unit", default=None, help="a generic CSV's acceleration unit (g, mg, m/s^2) when its names say none"
    )
    p.set_defaults(func=cmd_level)


def cmd_level(args: argparse.Namespace) -> int:
    from accelnav.data.imu import read_imu, write_level_csv
    from accelnav.level import level_frame

    imu = read_imu(args.log, unit=args.unit)
    for line in imu.notes:
        print(line)
    result = level_frame(imu)
    for line in result.notes:
        print(line)
    print(result.summary())
    write_level_csv(args.out, result, inputs=[args.log])
    print(f"wrote {args.out}")
    return 0
