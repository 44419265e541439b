"""What the library says on its own: notes through :mod:`logging`, and a small progress display.

Notes (how a clock was read, samples filled in, how columns were taken) are ``INFO`` records of the
logger named after the module that speaks (``accelnav.data.inputs``, ...); what went wrong and was
recovered from (a cache entry rebuilt) is a ``WARNING``. The library never prints them: the
``accelnav`` command shows them as its lines (``-q`` silences them), a program or notebook chooses
with :mod:`logging` (docs/python.rst).

The progress display draws on stderr only when stderr is a terminal (or when forced), redraws at most
ten times a second, and costs one comparison per call otherwise, so it can sit in a loop over chunks
without slowing it down.
"""

from __future__ import annotations

import logging
import sys
import time

VERBOSITY = 1  # progress bars: 0 never, 1 on a terminal, 2 always


def set_verbosity(level: int) -> None:
    """When progress bars draw: 0 never, 1 when stderr is a terminal, 2 always (the notes are logging's)."""
    global VERBOSITY
    VERBOSITY = int(level)


def note(text: str) -> None:
    """A note for the user, logged at INFO by the logger of the calling module (``accelnav.<module>``), so a
    user filters notes by where they come from without every caller naming its logger."""
    caller = sys._getframe(1).f_globals.get("__name__", "")
    name = caller if caller == "accelnav" or caller.startswith("accelnav.") else "accelnav"
    logging.getLogger(name).info(text)


class Progress:
    """``with Progress("filter", total=n) as p: ... p.update(done)``"""

    def __init__(
        self,
        label: str,
        total: int,
        *,
        stream=None,
        enabled: bool | None = None,
        unit: str = "samples",
        after: float = 0.0,
    ):
        """``after``: seconds of work before the first line is drawn (work done sooner draws nothing)."""
        self.label = label
        self.total = max(int(total), 1)
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            enabled = VERBOSITY >= 2 or (VERBOSITY >= 1 and bool(getattr(self.stream, "isatty", lambda: False)()))
        self.enabled = enabled
        self._t0 = time.monotonic()
        self._last = 0.0
        self.after = after
        self.drawn = False
        self.done = 0

    def update(self, done: int) -> None:
        self.done = done
        if not self.enabled:
            return
        now = time.monotonic()
        if now - self._last < 0.1 and done < self.total or now - self._t0 < self.after:
            return
        self.drawn = True
        self._last = now
        frac = min(done / self.total, 1.0)
        elapsed = now - self._t0
        rate = done / elapsed if elapsed > 0 else 0.0
        eta = (self.total - done) / rate if rate > 0 else 0.0
        bar = "#" * int(frac * 24)
        self.stream.write(
            f"\r{self.label:>10} [{bar:<24}] {100 * frac:5.1f}%  {rate:,.0f} {self.unit}/s  eta {eta:4.0f} s "
        )
        self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc) -> None:
        if self.enabled:
            self.update(self.total if exc[0] is None else self.done)
        if self.drawn:
            self.stream.write("\n")
            self.stream.flush()
