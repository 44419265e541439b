"""The firmware sources (C, board files, firmware.mk), shipped as package data.

Nothing here is Python: see firmware/README.md and accelnav.hil_sim.targets.firmware.
"""

__all__: list[str] = []  # data only: nothing to import
