"""``fault-monitor``: the command-line entry point.

Each sub-command lives in ``monitor.commands.<name>`` with a ``register(subparsers)`` function that adds
its parser and sets ``func``. Heavy imports (cvxpy, zenoh, rerun) happen inside the commands, so that
``--help`` is instant. Errors the user can fix are one line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from monitor import __version__
from monitor.errors import run_cli_command

COMMANDS = ("design", "verify", "margin", "threshold", "run", "analyse", "subscribe", "replay", "router", "demo")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fault-monitor",
        description=(
            "Estimate and compensate a UAV actuator fault live over MAVLink, under an uncertain short network "
            "delay (IEEE Access 2021 integrated FE/FTC design, repaired and certified). Offline: design and "
            "verify gains. Online: run the monitor daemon, subscribe to its estimates, replay its recordings."
        ),
        epilog="Start with: fault-monitor demo --out demo-out   (see README.md)",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    parser.add_argument("--log-level", default="INFO", choices=("DEBUG", "INFO", "WARNING", "ERROR"),
                        help="log verbosity on stderr (default: INFO)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"monitor.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"monitor.commands.{name}":
                continue
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=getattr(logging, args.log_level), format="%(asctime)s %(name)s %(levelname)s %(message)s",
                        stream=sys.stderr)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return run_cli_command("fault-monitor", args)


if __name__ == "__main__":
    sys.exit(main())
