"""``--mavlink`` connection strings and the operator mistakes around them: one line, exit 2."""

from __future__ import annotations

import socket
import subprocess
import sys

import pytest

from monitor.errors import UserError
from monitor.link.transports import ConnectionSpec, parse_connection, resolve


@pytest.mark.parametrize("text, spec", [
    ("udpin:127.0.0.1:14550", ConnectionSpec("udpin", "127.0.0.1", 14550)),
    ("udp:127.0.0.1:14550", ConnectionSpec("udpin", "127.0.0.1", 14550)),
    ("udpout:localhost:14551", ConnectionSpec("udpout", "localhost", 14551)),
    ("tcp:127.0.0.1:5760", ConnectionSpec("tcp", "127.0.0.1", 5760)),
    ("tcpin:[::1]:5761", ConnectionSpec("tcpin", "::1", 5761)),
])
def test_connections_as_mavproxy_writes_them(text: str, spec: ConnectionSpec) -> None:
    assert parse_connection(text) == spec


@pytest.mark.parametrize("text", ["udpin:127.0.0.1", "serial:/dev/ttyUSB0:57600", "tcp:127.0.0.1:0",
                                  "udpin:127.0.0.1:70000", "127.0.0.1:14550"])
def test_bad_connections_are_one_line(text: str) -> None:
    with pytest.raises(UserError, match="expected udpin:HOST:PORT|needs the peer's port"):
        parse_connection(text)


def test_an_unresolvable_host_is_one_line() -> None:
    with pytest.raises(UserError, match="cannot resolve host 'no-such-host.invalid'"):
        resolve(parse_connection("udpout:no-such-host.invalid:14550"))


def test_mavlink_port_in_use_is_one_line_exit_2(tmp_path) -> None:
    from tests.test_service_vehicles import _gains_file

    gains = _gains_file(tmp_path / "gains.toml")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        out = subprocess.run([sys.executable, "-m", "monitor", "run", "--plant", "paper-continuous", "--gains",
                              str(gains), "--mavlink", f"udpin:127.0.0.1:{port}"], capture_output=True, text=True,
                             timeout=60)
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if "error" in line]
    assert len(lines) == 1 and "in use" in lines[0] and "Traceback" not in out.stderr, out.stderr
