"""``fault-monitor subscribe``: print live estimates (or any JSON key) as one JSON line per sample.

The small client other services can copy: a Zenoh client session on explicit endpoints, a ring-buffer
handler read from the main thread (no callback thread left behind at exit), and a bounded close.
"""

from __future__ import annotations

import argparse

__all__ = ["register"]


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "subscribe",
        help="print live fault estimates from Zenoh as JSON lines",
        description="Print every sample on KEYEXPR as one JSON line on stdout until SIGINT/SIGTERM, --count or "
        "--duration. Connect to a monitor (peer) or a router with --zenoh-connect. The estimates of a monitor group "
        '(run --group) come from the member that answered each sample and name it ("member").',
    )
    p.add_argument(
        "keyexpr",
        nargs="?",
        default=None,
        metavar="KEYEXPR",
        help="key expression (default: <prefix>/*/fault/estimate)",
    )
    p.add_argument("--count", type=int, metavar="N", help="exit after N samples (default: until a signal)")
    p.add_argument("--duration", type=float, metavar="S", help="exit after S seconds (default: until a signal)")
    from monitor.wire.zenoh_session import add_zenoh_arguments

    add_zenoh_arguments(p)
    p.set_defaults(func=subscribe, zenoh_mode="client")


def subscribe(args: argparse.Namespace) -> int:
    import json
    import signal
    import sys
    import threading
    import time

    import zenoh

    from monitor.errors import UserError
    from monitor.wire.zenoh_session import close_quietly, config_from_args, open_session

    if args.zenoh_mode == "client" and not args.zenoh_connect and not args.zenoh_config:
        raise UserError(
            "a client needs --zenoh-connect EP (a monitor's --zenoh-listen endpoint or a router), "
            "or use --zenoh-mode peer"
        )
    keyexpr = args.keyexpr or f"{args.key_prefix.rstrip('/')}/*/fault/estimate"
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    session = open_session(config_from_args(args))
    sub = None
    try:
        try:
            sub = session.declare_subscriber(keyexpr, zenoh.handlers.RingChannel(10_000))
        except Exception as exc:
            raise UserError(f"bad key expression '{keyexpr}': {str(exc).splitlines()[0]}") from None
        deadline = time.monotonic() + args.duration if args.duration is not None else None
        printed = 0
        while not stop.is_set() and (args.count is None or printed < args.count):
            if deadline is not None and time.monotonic() >= deadline:
                break
            sample = sub.try_recv()
            if sample is None:
                stop.wait(0.01)
                continue
            raw = sample.payload.to_bytes()
            try:
                line = json.dumps(json.loads(raw), separators=(",", ":"))
            except ValueError:  # not JSON: print it as a JSON string, still one line
                line = json.dumps({"key": str(sample.key_expr), "payload": raw.decode("utf-8", "replace")})
            try:
                sys.stdout.write(line + "\n")
                sys.stdout.flush()
            except BrokenPipeError:  # `| head` closed the pipe: a normal way to stop
                break
            printed += 1
    finally:
        close_quietly(session, sub)
    return 0
