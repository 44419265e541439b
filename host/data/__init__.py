"""Files a user brings or keeps: recordings in (recording) and accelnav run files (runfile)."""

# its modules, which users import by name (``from accelnav.data import inputs``)
__all__ = [
    "csvnum",
    "inputs",
    "logs",
    "recording",
    "run",
    "runfile",
    "stream",
]
