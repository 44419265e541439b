"""A serial link that goes away and comes back: a TCP server on 127.0.0.1 (pyserial's socket://) that serves
each part on its own connection, the port closed in between. Shared by the recorder's and the compact
mode's reconnect tests."""

from __future__ import annotations

import socket
import threading
import time


def _serve(srv: socket.socket, parts: list[bytes], down_s: float, log: list) -> None:
    """Serve ``parts`` one connection each on ``srv``'s port, the port closed for ``down_s`` between them."""
    port = srv.getsockname()[1]
    for k, data in enumerate(parts):
        if k:
            time.sleep(down_s)  # nobody listens: the recorder's attempts are refused
            srv = socket.socket()
            srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            srv.bind(("127.0.0.1", port))
            srv.listen(1)
        srv.settimeout(20)
        try:
            conn, _ = srv.accept()
        except OSError:
            srv.close()
            return
        conn.settimeout(0.3)
        try:  # the recorder's commands, or a pause: pyserial drops what arrives while it opens the socket
            conn.recv(4096)
        except OSError:
            pass
        conn.sendall(data)
        try:  # read what the recorder sends (its commands) until it is quiet: closing on unread bytes resets
            while conn.recv(4096):
                pass
        except OSError:
            pass
        conn.shutdown(socket.SHUT_RDWR)  # the cable is pulled
        conn.close()
        srv.close()
        log.append(time.monotonic())


def server(parts, down_s):
    srv = socket.socket()
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", 0))
    srv.listen(1)
    log: list = []
    th = threading.Thread(target=_serve, args=(srv, parts, down_s, log), daemon=True)
    th.start()
    return f"socket://127.0.0.1:{srv.getsockname()[1]}", th, log
