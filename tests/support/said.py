"""What the library said through :mod:`logging` (accelnav.progress's notes, the caches' warnings), as lists of
messages: the tests' view of the lines the command prints."""

from __future__ import annotations

import logging


def listen(caplog) -> None:
    """Capture the ``accelnav`` loggers' notes (INFO) as well as their warnings."""
    caplog.set_level(logging.INFO, logger="accelnav")


def _said(caplog, keep) -> list[str]:
    return [
        r.getMessage()
        for r in caplog.records
        if (r.name == "accelnav" or r.name.startswith("accelnav.")) and keep(r.levelno)
    ]


def notes(caplog) -> list[str]:
    """The notes (INFO) logged so far, oldest first."""
    return _said(caplog, lambda level: level == logging.INFO)


def warned(caplog) -> list[str]:
    """The warnings (WARNING and above) logged so far, oldest first."""
    return _said(caplog, lambda level: level >= logging.WARNING)


def one_warning(caplog) -> str:
    """The one warning logged since the last call (checked to be one), forgotten for the next."""
    lines = warned(caplog)
    caplog.clear()
    assert len(lines) == 1, lines
    return lines[0]
