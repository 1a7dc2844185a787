"""``--log-level`` on a program and on every one of its sub-commands, and the logging set-up it drives.

Why both places: people write ``fault-monitor --log-level DEBUG run`` as often as ``fault-monitor run
--log-level DEBUG``; each program used to accept only one of the two, and a different one each. The flag
is defined once here and added to the top-level parser and to every sub-command parser.

Why the sub-command copy defaults to ``argparse.SUPPRESS``: argparse copies every attribute of the
sub-command's namespace over the top-level one, so a sub-command default would silently undo a level
given before the sub-command.
"""

from __future__ import annotations

import argparse
import logging
import sys
from collections.abc import Iterable

__all__ = ["LEVELS", "DEFAULT_LEVEL", "add_log_level", "add_log_level_everywhere", "configure_logging"]

LEVELS = ("DEBUG", "INFO", "WARNING", "ERROR")
DEFAULT_LEVEL = "INFO"
FORMAT = "%(asctime)s %(name)s %(levelname)s %(message)s"


def _level(text: str) -> str:
    """Accept ``debug`` as well as ``DEBUG`` (argparse checks the result against ``LEVELS``)."""
    return str(text).upper()


def add_log_level(parser: argparse.ArgumentParser, top: bool = False) -> None:
    """Add ``--log-level`` to ``parser`` (``top``: the program's own parser, the one that holds the default)."""
    parser.add_argument(
        "--log-level",
        type=_level,
        choices=LEVELS,
        metavar="LEVEL",
        default=DEFAULT_LEVEL if top else argparse.SUPPRESS,
        help=f"log verbosity on stderr: {', '.join(LEVELS)} (default: {DEFAULT_LEVEL})",
    )


def _subparsers(parser: argparse.ArgumentParser) -> Iterable[argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            yield from action.choices.values()


def add_log_level_everywhere(parser: argparse.ArgumentParser) -> None:
    """``--log-level`` on ``parser`` and on each of its sub-commands that does not define it already."""
    add_log_level(parser, top=True)
    for sub in _subparsers(parser):
        if "--log-level" not in sub._option_string_actions:
            add_log_level(sub)


def configure_logging(args: argparse.Namespace) -> None:
    """Log to stderr at the level the command line (or a ``--config`` file) asked for."""
    level = getattr(logging, str(getattr(args, "log_level", None) or DEFAULT_LEVEL).upper(), logging.INFO)
    logging.basicConfig(level=level, format=FORMAT, stream=sys.stderr)
