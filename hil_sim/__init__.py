"""Sensor and trajectory simulator, SIL (cffi) and PIL (QEMU) runners."""
