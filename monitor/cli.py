"""``fault-monitor``: the command-line entry point.

Each sub-command lives in ``monitor.commands.<name>`` with a ``register(subparsers)`` function that adds
its parser and sets ``func``. Heavy imports (cvxpy, zenoh, rerun) happen inside the commands, so that
``--help`` is instant. Errors the user can fix are one line on stderr, never a traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from monitor import __version__
from monitor.cli_logging import add_log_level_everywhere, configure_logging
from monitor.config_file import parse_args_with_config
from monitor.errors import UserError, run_cli_command

COMMANDS = (
    "design",
    "verify",
    "margin",
    "threshold",
    "detectability",
    "run",
    "analyse",
    "identify",
    "envelope",
    "subscribe",
    "replay",
    "router",
    "demo",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fault-monitor",
        description=(
            "Estimate and compensate a UAV actuator fault live over MAVLink, under an uncertain short network "
            "delay (IEEE Access 2021 integrated FE/FTC design, repaired and certified). Offline: design and "
            "verify gains. Online: run the monitor daemon, subscribe to its estimates, replay its recordings."
        ),
        epilog="Start with: fault-monitor demo --out demo-out   (see docs/index.md)",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"monitor.commands.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"monitor.commands.{name}":
                continue
            raise
        module.register(sub)
    add_log_level_everywhere(parser)  # before or after the sub-command, on every one of them
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parse_args_with_config(parser, argv)  # a command with --config FILE is preset from FILE
    except UserError as exc:
        print(f"fault-monitor: error: {exc}", file=sys.stderr)
        return exc.exit_code
    configure_logging(args)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    return run_cli_command("fault-monitor", args)


if __name__ == "__main__":
    sys.exit(main())
