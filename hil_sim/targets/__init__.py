"""Where the generated C runs: in-process (SIL, cffi), on emulated boards (PIL), and the per-axis harness."""

# its modules, which users import by name (``from accelnav.hil_sim.targets import firmware``)
__all__ = [
    "firmware",
    "harness",
    "hil",
    "qemu",
    "simavr",
]
