"""The live plot of a recording: raw acceleration and the firmware's position estimate, last few seconds.

One drawing code serves a recording under way (``accelnav record --live-plot``) and a recorded stream
replayed (``accelnav log plot``). Why a PNG refreshed in place plus a page on 127.0.0.1 rather than a
GUI window: the recorder's loop must never wait for a drawing, and GUI toolkits (Tk, Qt) insist on
drawing from the main thread, which is the recorder's. The Agg canvas draws from any thread, works with
no display (a bench PC over ssh, CI) and the page shows it in any browser, reloading itself.

The recorder only appends rows to a bounded ring buffer (:meth:`LivePlot.push`, a copy under a lock); a
daemon thread redraws at most ``1 / interval_s`` times a second from a snapshot of it.
"""

from __future__ import annotations

import http.server
import logging
import threading
from pathlib import Path

import numpy as np

from accelnav.errors import UserError
from accelnav.fileio import atomic_output
from accelnav.link.manifest import Manifest, sample_columns

RING_SECONDS = 10.0  # what a person on a bench watches: the last few seconds
REFRESH_S = 0.5


class LivePlot:
    """A ring buffer of the last ``seconds`` of samples and the figure drawn from it.

    ``model`` (a :class:`accelnav.model.Model` or None) converts the raw input to m/s^2 with the model's
    own conversion; without one the raw input is plotted as it came (ADC codes, duty T1/T2)."""

    def __init__(self, manifest: Manifest, model=None, seconds: float = RING_SECONDS):
        self.man = manifest
        self.capacity = max(2, int(round(seconds * manifest.rate_hz)))
        n_axes = len(manifest.axes)
        self._t = np.full(self.capacity, np.nan)
        self._a = np.full((self.capacity, n_axes), np.nan)
        self._r = np.full((self.capacity, n_axes), np.nan)
        self._n = 0  # rows pushed so far; the newest sits at (_n - 1) % capacity
        self._lock = threading.Lock()  # the ring: the recorder writes, the drawing thread reads
        self._draw_lock = threading.Lock()  # the figure: one drawer at a time
        self._fig = None
        self._conv = None
        if model is not None:
            from accelnav.model import input_conversion

            self._conv = [input_conversion(model, j) for j in range(n_axes)]

    def push(self, rows: np.ndarray) -> None:
        """Append decoded sample rows (the decoder's structured array); only the last ``capacity`` stay."""
        if not len(rows):
            return
        n_new = len(rows)  # counted whole; only the last capacity of them can stay
        rows = rows[-self.capacity :]
        cols = sample_columns(self.man, rows)
        raw = [cols[f] for f in self.man.raw_fields()]
        if self._conv is None:
            a = raw[0].astype(np.float64)  # duty: T1 alone; T2 is the period, flat
        else:
            a = np.column_stack([c.accel(*(x[:, j] for x in raw)) for j, c in enumerate(self._conv)])
        with self._lock:
            k = (self._n + n_new - len(rows) + np.arange(len(rows))) % self.capacity
            self._t[k] = cols["t"]
            self._a[k] = a
            self._r[k] = cols["r"]
            self._n += n_new

    @property
    def pushed(self) -> int:
        return self._n

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t, raw acceleration, firmware r) of the rows held, oldest first."""
        with self._lock:
            n = min(self._n, self.capacity)
            k = (self._n - n + np.arange(n)) % self.capacity
            return self._t[k].copy(), self._a[k].copy(), self._r[k].copy()

    def figure(self):
        """The matplotlib Figure (Agg canvas: no GUI, any thread) showing what the buffer holds now.

        Built once, then only its lines' data, limits and title change: a fresh figure with its layout
        cost several times the redraw itself."""
        t, a, r = self.snapshot()
        with self._draw_lock:
            if self._fig is None:
                self._fig = self._build()
            fig = self._fig
            ax_a, ax_r = fig.axes
            for j in range(len(self.man.axes)):
                ax_a.get_lines()[j].set_data(t, a[:, j])
                ax_r.get_lines()[j].set_data(t, r[:, j])
            for ax in (ax_a, ax_r):
                ax.relim()
                ax.autoscale_view()
            last = "no samples yet"
            if len(t):
                last = ", ".join(f"{n}={v:+.3f} m" for n, v in zip(self.man.axes, r[-1], strict=True))
            fig.texts[0].set_text(f"accelnav live: {self._n} samples; last r: {last}")
            return fig

    def _build(self):
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(9, 6.5), dpi=90)
        fig.subplots_adjust(left=0.09, right=0.98, top=0.9, bottom=0.08, hspace=0.28)  # fixed: no layout per redraw
        FigureCanvasAgg(fig)
        ax_a, ax_r = fig.subplots(2, 1, sharex=True)
        unit = "m/s^2" if self._conv is not None else self.man.raw_fields()[0]
        for name in self.man.axes:
            ax_a.plot([], [], lw=0.8, label=name)
            ax_r.plot([], [], lw=1.4, label=name)
        ax_a.set_title(f"raw acceleration [{unit}]" if self._conv is not None else f"raw input [{unit}]")
        ax_r.set_title("firmware position estimate r [m]")
        ax_a.set_ylabel(unit)
        ax_r.set_ylabel("m")
        ax_r.set_xlabel("time [s] (sample index / rate)")
        for ax in (ax_a, ax_r):
            ax.grid(True, alpha=0.3)
            ax.legend(loc="upper left", fontsize=8)
        fig.suptitle("accelnav live")
        return fig

    def save(self, path: str | Path) -> Path:
        """Draw and write a PNG in place: to a hidden file beside it, then renamed, so a viewer never reads
        half a file. No fsync: this is a view, redrawn a moment later, not data."""
        fig = self.figure()
        with self._draw_lock, atomic_output(path, flag="live plot", fsync=False) as fh:  # the output rule
            fig.savefig(fh, format="png")
        return Path(path)


class LiveView:
    """Redraw ``plot`` to ``png`` every ``interval_s`` from a daemon thread while anything new came, and
    optionally serve a self-reloading page of it on 127.0.0.1:``port`` (0: any free port). The page answers
    only requests naming this machine (:func:`host_allowed`);
    ``log`` gets one line per refused Host (default: a warning of this module's logger)."""

    def __init__(
        self,
        plot: LivePlot,
        png: str | Path,
        interval_s: float = REFRESH_S,
        port: int | None = None,
        log=None,
    ):
        self.plot = plot
        self.png = Path(png)
        self.interval_s = interval_s
        self.frames_drawn = 0
        self.error: str | None = None  # why drawing stopped (a full disk): the recording carries on
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="accelnav-live-plot", daemon=True)
        self._server = None
        self.url: str | None = None
        if port is not None:
            self._server = _serve(self.png, port, interval_s, log or _log_warning)
            self.url = f"http://127.0.0.1:{self._server.server_address[1]}/"

    def start(self) -> LiveView:
        self._thread.start()
        return self

    def _loop(self) -> None:
        drawn = -1
        while not self._stop.wait(self.interval_s):
            self._draw_if_new(drawn)
            drawn = self.plot.pushed

    def _draw_if_new(self, drawn: int) -> None:
        if self.plot.pushed == drawn or self.error:
            return
        try:
            self.plot.save(self.png)
            self.frames_drawn += 1
        except OSError as exc:
            self.error = f"{self.png}: {exc.strerror or exc}"
        except UserError as exc:  # the output rule's one line (a full disk, another writer)
            self.error = str(exc)

    def close(self) -> None:
        """Stop the thread, draw the final state once, stop the page."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(5)
        self._draw_if_new(-1)
        if self._server is not None:
            self._server.shutdown()
            self._server.server_close()


_PAGE = (
    '<!doctype html><html><head><meta charset="utf-8"><title>accelnav live</title>'
    '<meta http-equiv="refresh" content="{refresh}"></head>'
    '<body style="margin:0;background:#fff"><img src="live.png" style="max-width:100%"></body></html>'
)


LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")


def host_allowed(host: str | None, port: int) -> bool:
    """Is ``host`` (a request's Host header) this machine's loopback on ``port``? Binding 127.0.0.1 keeps other
    machines out, but a page from elsewhere can point its own name at 127.0.0.1 (DNS rebinding) and read
    ours as same-origin; its requests then carry its name in Host, so only loopback names pass."""
    if host is None:
        return False
    return host.strip().lower() in {f"{name}:{port}" for name in LOOPBACK_NAMES}


def _log_warning(line: str) -> None:
    logging.getLogger(__name__).warning("live plot: %s", line)


def _serve(png: Path, port: int, interval_s: float, log):
    """A page and the PNG on 127.0.0.1 only, from a daemon thread. No option binds another address: the plot
    is for the person at this machine. Requests whose Host is not a loopback name with our port get 403; each
    such Host is logged once (a rebinding page retries: the log stays bounded)."""
    refused: set[str] = set()

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 (http.server's name)
            host = self.headers.get("Host")
            bound = self.server.server_address[1]
            if not host_allowed(host, bound):
                self.send_error(403, "Host not allowed")
                shown = repr(host)[:80]
                if shown not in refused and len(refused) < 100:
                    refused.add(shown)
                    names = ", ".join(LOOPBACK_NAMES)
                    log(f"refused a request with Host {shown} (403): only {names} on port {bound}")
                return
            if self.path.split("?")[0] == "/live.png":
                try:
                    body, kind = png.read_bytes(), "image/png"
                except OSError:
                    self.send_error(404, "no plot drawn yet")
                    return
            elif self.path in ("/", "/index.html"):
                body, kind = _PAGE.format(refresh=max(1, round(interval_s * 2))).encode(), "text/html"
            else:
                self.send_error(404)
                return
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.send_header("Cache-Control", "no-store")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):  # the recorder's status line owns stderr
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)
    threading.Thread(target=server.serve_forever, name="accelnav-live-page", daemon=True).start()
    return server


def plot_log(log: str | Path, out: str | Path, model_text: str = "", seconds: float = RING_SECONDS) -> LivePlot:
    """Replay a recorded stream through the live plot (the same ring buffer and drawing) and write ``out``:
    what the live view showed when the recording ended."""
    from accelnav.link.recorder import decode_log
    from accelnav.model.load import loads_model

    d = decode_log(log, model_text)
    text = d.meta.get("model_toml") or model_text
    model = loads_model(text, source=f"{log}:model_toml") if text else None
    plot = LivePlot(d.manifest, model, seconds)
    plot.push(d.frames["sample"])
    plot.save(out)
    return plot
