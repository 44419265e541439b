"""The live plot's page answers only requests that name this machine: a DNS-rebinding page (its own name
resolved to 127.0.0.1) sends its name in Host and gets 403, logged in one line. A real socket on 127.0.0.1."""

from __future__ import annotations

import socket

import pytest

from accelnav.plots.live import LivePlot, LiveView, host_allowed


def _get(port: int, host: str | None) -> tuple[int, bytes]:
    """(status, body) of GET / with the Host header given as-is (None: an HTTP/1.0 request without one)."""
    head = "GET / HTTP/1.0\r\n" if host is None else f"GET / HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n"
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        s.sendall((head + "\r\n").encode())
        data = b""
        while chunk := s.recv(65536):
            data += chunk
    status = int(data.split(b" ", 2)[1])
    return status, data.split(b"\r\n\r\n", 1)[1]


@pytest.fixture
def served(man, tmp_path):
    lines: list[str] = []
    view = LiveView(LivePlot(man, None, seconds=1), tmp_path / "x.live.png", port=0, log=lines.append)
    try:
        yield view, view._server.server_address, lines
    finally:
        view.close()


def test_the_page_is_bound_to_loopback_only(served):
    _, (addr, _), _ = served
    assert addr == "127.0.0.1"


@pytest.mark.parametrize("name", ["127.0.0.1", "localhost", "LocalHost", "[::1]"])
def test_loopback_names_with_the_bound_port_are_served(served, name):
    _, (_, port), lines = served
    status, body = _get(port, f"{name}:{port}")
    assert status == 200 and b'src="live.png"' in body
    assert lines == []


@pytest.mark.parametrize(
    "host",
    ["evil.example:{port}", "evil.example", "127.0.0.1", "127.0.0.1:{other}", "localhost.evil.example:{port}", ""]
    + [None],
)
def test_any_other_host_gets_403_and_one_log_line(served, host):
    _, (_, port), lines = served
    forged = None if host is None else host.format(port=port, other=port + 1 if port < 65535 else port - 1)
    status, body = _get(port, forged)
    assert status == 403 and b"live.png" not in body
    assert len(lines) == 1 and "\n" not in lines[0], lines
    assert lines[0].startswith(f"refused a request with Host {forged!r} (403)") and f"port {port}" in lines[0]
    _get(port, forged)  # the same page retrying: no second line
    assert len(lines) == 1


def test_host_allowed_is_exact():
    assert host_allowed("127.0.0.1:8080", 8080)
    assert not host_allowed("127.0.0.1:8080", 8081)
    assert not host_allowed("127.0.0.1.nip.io:8080", 8080)
    assert not host_allowed(None, 8080)
