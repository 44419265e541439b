"""The simulator (sim/) and the runners that drive the generated C in-process and on emulated boards (targets/)."""

# its modules, which users import by name (``from accelnav.hil_sim import sim``)
__all__ = [
    "sim",
    "targets",
]
