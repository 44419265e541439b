"""Files a user brings or keeps: recordings in (recording; phone and IMU logs: imu) and accelnav run files (runfile)."""

# its modules, which users import by name (``from accelnav.data import inputs``)
__all__ = [
    "csvnum",
    "imu",
    "inputs",
    "logs",
    "recording",
    "run",
    "runfile",
    "stream",
]
