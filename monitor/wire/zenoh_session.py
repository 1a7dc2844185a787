"""Zenoh sessions for the monitor, the vehicle and the small clients: loopback by default, no scouting.

Why no multicast scouting: on a shared machine it would join whatever other Zenoh network is around,
and on CI it may not work at all. Peers find each other only through the endpoints they are given.

Why a guarded close: ``session.close()`` can block for seconds or raise when a peer froze, and a
callback subscriber left declared keeps a non-daemon thread alive, so a process could hang at exit.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import re
import socket
import threading
from collections.abc import Iterable
from pathlib import Path

import zenoh

from monitor.errors import UserError

__all__ = [
    "DEFAULT_PREFIX",
    "build_config",
    "open_session",
    "close_quietly",
    "add_zenoh_arguments",
    "config_from_args",
    "key",
]

DEFAULT_PREFIX = "uav"
log = logging.getLogger(__name__)


def key(prefix: str, sysid: int | str, *parts: str) -> str:
    """``<prefix>/<sysid>/<parts...>``, e.g. ``uav/1/fault/estimate``."""
    return "/".join([prefix.rstrip("/"), str(sysid), *parts])


def build_config(
    listen: Iterable[str] = (),
    connect: Iterable[str] = (),
    config_file: str | None = None,
    mode: str = "peer",
) -> zenoh.Config:
    """A Zenoh config from explicit endpoints (``tcp/127.0.0.1:7447``) with multicast and gossip scouting off.

    With neither listen nor connect endpoints a peer listens on an ephemeral loopback port only, so that
    nothing is ever exposed beyond this machine by default.
    """
    listen = list(listen)
    connect = list(connect)
    if config_file:
        try:
            conf = zenoh.Config.from_file(str(Path(config_file)))
        except Exception as exc:  # zenoh raises its own ZError with a long message
            raise UserError(f"{config_file}: not a valid Zenoh config: {zenoh_message(exc)}") from None
    else:
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(mode))
        conf.insert_json5("scouting/multicast/enabled", "false")
        conf.insert_json5("scouting/gossip/enabled", "false")
        if not listen and mode != "client":
            listen = ["tcp/127.0.0.1:0"]
    for endpoint in listen + connect:
        check_endpoint(endpoint)
    try:
        if listen:
            conf.insert_json5("listen/endpoints", json.dumps(listen))
        if connect:
            conf.insert_json5("connect/endpoints", json.dumps(connect))
    except Exception as exc:
        raise UserError(f"bad Zenoh endpoint in {listen + connect}: {zenoh_message(exc)}") from None
    return conf


_RUST_SOURCE = re.compile(r"\s+at /\S+\.rs:\d+\.?")


def zenoh_message(exc: BaseException) -> str:
    """Zenoh's error text on one line, without the Rust source paths it appends (they help nobody here)."""
    text = _RUST_SOURCE.sub("", str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
    match = re.search(r'msg: "(.*?)"', text)  # JSON5 config errors wrap the useful part
    return match.group(1) if match else text


def check_endpoint(endpoint: str) -> None:
    """``tcp/HOST:PORT`` (or udp, tls, quic, ws): a one-line UserError for what Zenoh would retry forever.

    Zenoh accepts ``tcp/256.1.1.1:7447`` and then silently fails to connect; a typo in an address
    should stop the daemon at start, not leave it running alone.
    """
    proto, sep, rest = endpoint.partition("/")
    address = rest.split("?", 1)[0].split("#", 1)[0]
    host, _, port = address.rpartition(":")
    if not sep or proto not in ("tcp", "udp", "tls", "quic", "ws"):
        if sep and proto.startswith("unixsock"):
            return
        raise UserError(f"Zenoh endpoint '{endpoint}': expected PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447")
    host = host[1:-1] if host.startswith("[") and host.endswith("]") else host
    if not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"Zenoh endpoint '{endpoint}': expected PROTOCOL/HOST:PORT with a port 0-65535")
    try:
        ipaddress.ip_address(host)
    except ValueError:
        if re.fullmatch(r"[0-9.]+", host):
            raise UserError(f"Zenoh endpoint '{endpoint}': '{host}' is not a valid IP address") from None
        try:
            socket.getaddrinfo(host, int(port))
        except (socket.gaierror, UnicodeError):
            raise UserError(f"Zenoh endpoint '{endpoint}': cannot resolve host '{host}'") from None


def open_session(conf: zenoh.Config) -> zenoh.Session:
    """Open a session, turning Zenoh's multi-line errors (e.g. port in use) into one line."""
    try:
        return zenoh.open(conf)
    except Exception as exc:
        raise UserError(f"cannot open Zenoh session: {zenoh_message(exc)}") from None


def close_quietly(session: zenoh.Session | None, *entities, timeout: float = 5.0) -> None:
    """Undeclare entities, then close the session in a helper thread bounded by ``timeout`` seconds."""
    for entity in entities:
        if entity is None:
            continue
        try:
            entity.undeclare()
        except Exception as exc:  # already gone, or the session died: nothing left to release
            log.debug("undeclare failed: %s", exc)
    if session is None:
        return
    done = threading.Event()

    def _close() -> None:
        try:
            session.close()
        except Exception as exc:
            log.debug("zenoh close failed: %s", exc)
        finally:
            done.set()

    threading.Thread(target=_close, name="zenoh-close", daemon=True).start()
    if not done.wait(timeout):
        log.warning("Zenoh session did not close within %.0f s; exiting anyway", timeout)


def add_zenoh_arguments(parser, prefix_default: str = DEFAULT_PREFIX) -> None:
    """The Zenoh flags every command shares (one definition, not copies)."""
    group = parser.add_argument_group("Zenoh")
    group.add_argument(
        "--zenoh-listen",
        action="append",
        default=[],
        metavar="EP",
        help="endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable; none given: an ephemeral loopback port)",
    )
    group.add_argument(
        "--zenoh-connect",
        action="append",
        default=[],
        metavar="EP",
        help="endpoint of a peer or router to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    group.add_argument(
        "--zenoh-config",
        metavar="FILE",
        help="a Zenoh JSON5 config file (replaces the loopback, no-scouting settings above)",
    )
    group.add_argument(
        "--zenoh-mode",
        choices=("peer", "client", "router"),
        default="peer",
        help="Zenoh session mode (default: %(default)s)",
    )
    group.add_argument(
        "--key-prefix",
        default=prefix_default,
        metavar="PREFIX",
        help="key prefix, e.g. uav/<network> to keep overlapping system ids apart (default: %(default)s)",
    )


def config_from_args(args) -> zenoh.Config:
    return build_config(args.zenoh_listen, args.zenoh_connect, args.zenoh_config, args.zenoh_mode)
