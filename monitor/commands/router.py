"""``fault-monitor router``: a Zenoh router in the box, with the project's loopback / no-scouting defaults.

Why: ``zenohd`` is not installable from the package registry, and a fleet of monitors, vehicles and
subscribers wants one well-known place to meet (every daemon a client of it). A zenoh-python session in
``router`` mode is that router. Flags as zenohd's: ``-l/--listen EP`` and ``-e/--connect EP`` (repeatable),
``-c/--config FILE`` (a Zenoh JSON5 config; then the loopback, no-scouting defaults are not applied).
"""

from __future__ import annotations

import argparse

__all__ = ["register"]

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "router",
        help="a Zenoh router, so monitors, vehicles and subscribers on several hosts see each other",
        description=(
            "Run a Zenoh router: monitors, vehicles and subscribers connect to it as clients "
            "(--zenoh-mode client --zenoh-connect EP) and see each other's estimates, alarms and truth. "
            f"Listens on {DEFAULT_LISTEN} unless told otherwise; multicast and gossip scouting off. "
            "Stops on SIGINT/SIGTERM with exit code 0."
        ),
        epilog="Example: fault-monitor router -l tcp/127.0.0.1:7447   then   fault-monitor run ... "
        "--zenoh-mode client --zenoh-connect tcp/127.0.0.1:7447",
    )
    p.add_argument(
        "-l",
        "--listen",
        action="append",
        default=[],
        metavar="EP",
        help=f"endpoint to listen on (repeatable; default {DEFAULT_LISTEN})",
    )
    p.add_argument(
        "-e",
        "--connect",
        action="append",
        default=[],
        metavar="EP",
        help="another router or peer to connect to (repeatable)",
    )
    p.add_argument("-c", "--config", metavar="FILE", help="a Zenoh JSON5 config file, as zenohd's -c")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import logging
    import signal
    import threading

    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    log = logging.getLogger("monitor.router")
    listen = args.listen or ([] if args.config else [DEFAULT_LISTEN])
    session = open_session(build_config(listen, args.connect, args.config, mode="router"))
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        log.info(
            "ready: Zenoh router %s, listening on %s%s",
            session.zid(),
            ", ".join(listen) or "(config file)",
            f", connected to {', '.join(args.connect)}" if args.connect else "",
        )
        while not stop.wait(1.0):
            pass
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
        close_quietly(session)
    log.info("stopped")
    return 0
