"""Recording over pyserial's loop:// as the recorder tests do: bytes written from a thread (loop:// holds
4 KiB), more of them later if asked, the recorder run and closed."""

from __future__ import annotations

import threading

import serial

from accelnav.link.recorder import Recorder, Status


def record_loop(man, out, data: bytes, *, later: bytes = b"", later_s: float = 0.0, model_text: str = "", **kw):
    """Record ``data`` (then ``later`` after ``later_s`` s) into ``out``; ``kw``: ``baud`` for the Recorder,
    the rest for :meth:`Recorder.run`. Returns the run's Result."""
    port = serial.serial_for_url("loop://", timeout=0.02)
    writers = [threading.Thread(target=port.write, args=(data,), daemon=True)]
    if later:
        writers.append(threading.Timer(later_s, port.write, args=(later,)))
    baud = {"baud": kw.pop("baud")} if "baud" in kw else {}
    rec = Recorder(port, out, man, commands=(), model_text=model_text, status=Status(enabled=False), **baud)
    for w in writers:
        w.start()
    res = rec.run(**kw)
    rec.close()
    for w in writers:
        w.join(5)
    return res
