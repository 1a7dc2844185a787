"""TOML files whose keys preset a command's flags (``--config FILE``), shared by every daemon.

A file holds the long flag names, spelled with ``-`` or ``_``, and the values a flag would take::

    plant = "paper-continuous"
    gains = "/etc/fault-monitor/gains.toml"
    mavlink = ["udpin:127.0.0.1:14550"]     # a repeatable flag takes a list
    zenoh_listen = ["tcp/127.0.0.1:7447"]
    alarm_threshold = 1.0
    no_gcs_feedback = true                  # an on/off flag takes true/false

The values become the parser's defaults, so a flag given on the command line still wins. For a repeatable
flag that means the flags given *replace* the file's whole list (``--config monitor.toml --mavlink X``
listens on X alone); to add to the file's list, repeat its entries on the command line. One rule for every
flag, and a way to replace a list, which appending to it could not give.

Why strict: an unknown key (``dealy``) or a value of the wrong type silently ignored would run another
experiment than the one written down, so each is a one-line ``UserError`` naming the key and the file.
Why here and not in each program: ``sim-vehicle run`` and ``fault-monitor run`` must read their files
the same way; one reader, one set of rules.
"""

from __future__ import annotations

import argparse
import tomllib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from monitor.errors import UserError

__all__ = ["read_config", "config_defaults", "apply_config_file", "parse_args_with_config"]

# dests no file may set: they steer argparse itself, not the program
_RESERVED = frozenset({"help", "version", "config", "func", "command"})


def read_config(path: str | Path) -> dict[str, Any]:
    """The TOML table in ``path``, or a one-line ``UserError`` (missing, unreadable, not TOML)."""
    try:
        return tomllib.loads(Path(path).read_text("utf-8"))
    except OSError as exc:
        raise UserError(f"--config {path}: cannot read: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise UserError(f"--config {path}: not valid TOML: {exc}") from None


def _flag_names(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """``{key: action}`` for every long flag (``--zenoh-listen`` -> ``zenoh_listen``) a file may set."""
    names: dict[str, argparse.Action] = {}
    for action in parser._actions:
        if action.dest in _RESERVED or isinstance(
            action, (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)
        ):
            continue
        for option in action.option_strings:
            if option.startswith("--"):
                names[option[2:].replace("-", "_")] = action
    return names


def _describe(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _scalar(action: argparse.Action, value: Any, where: str) -> Any:
    """One value converted as the flag's ``type`` would convert its text, and checked against ``choices``."""
    if isinstance(value, (dict, list)) or isinstance(value, bool):
        raise UserError(f"{where}: expected {_expected(action)}, got {_describe(value)}")
    convert = action.type
    if convert is None:
        out: Any = value if isinstance(value, str) else str(value)
    elif convert is float:
        if not isinstance(value, (int, float)):
            raise UserError(f"{where}: expected a number, got {_describe(value)}")
        out = float(value)
    elif convert is int:
        if not isinstance(value, int):
            raise UserError(f"{where}: expected an integer, got {_describe(value)}")
        out = value
    else:
        try:
            # typeshed lets Action.type be a registry name (a str); the parser's types are all callables
            out = convert(value if isinstance(value, str) else str(value))  # type: ignore[operator]
        except (TypeError, ValueError, argparse.ArgumentTypeError) as exc:
            raise UserError(f"{where}: {exc}") from None
    if action.choices is not None and out not in action.choices:
        raise UserError(f"{where}: {_describe(value)} is not one of {', '.join(map(str, action.choices))}")
    return out


def _expected(action: argparse.Action) -> str:
    if action.type is float:
        return "a number"
    if action.type is int:
        return "an integer"
    return "a string"


def _value(action: argparse.Action, value: Any, where: str) -> Any:
    """The default ``action`` should take for a file's ``value``."""
    if action.nargs == 0:  # store_true / store_false / store_const: an on/off switch
        if not isinstance(value, bool):
            raise UserError(f"{where}: expected true or false, got {_describe(value)}")
        return action.const if value else action.default
    repeatable = (
        isinstance(action, argparse._AppendAction) or action.nargs in ("*", "+") or isinstance(action.nargs, int)
    )
    if repeatable:
        items = value if isinstance(value, list) else [value]
        return [_scalar(action, v, f"{where}[{i}]") for i, v in enumerate(items)]
    if isinstance(value, list) and action.type is None:
        # comma-separated flags (--x0 0.1,0, --autopilot 1,2) read naturally as TOML arrays
        if not all(isinstance(v, (str, int, float)) and not isinstance(v, bool) for v in value):
            raise UserError(f"{where}: expected a string or a list of numbers, got {_describe(value)}")
        return ",".join(str(v) for v in value)
    return _scalar(action, value, where)


def config_defaults(parser: argparse.ArgumentParser, raw: dict[str, Any], path: str | Path) -> dict[str, Any]:
    """``{dest: value}`` from a file's keys, each checked against the flag it names (strict, one-line errors).

    >>> p = argparse.ArgumentParser()
    >>> _ = p.add_argument("--zenoh-listen", action="append", default=[])
    >>> _ = p.add_argument("--speedup", type=float, default=1.0)
    >>> _ = p.add_argument("--no-truth", dest="truth", action="store_false")
    >>> config_defaults(p, {"zenoh-listen": ["tcp/127.0.0.1:7447"], "speedup": 20, "no_truth": True}, "f.toml")
    {'zenoh_listen': ['tcp/127.0.0.1:7447'], 'speedup': 20.0, 'truth': False}
    >>> config_defaults(p, {"dealy": 1}, "f.toml")
    Traceback (most recent call last):
    monitor.errors.UserError: --config f.toml: unknown key 'dealy' (known: no_truth, speedup, zenoh_listen)
    """
    names = _flag_names(parser)
    out: dict[str, Any] = {}
    for key, value in raw.items():
        action = names.get(str(key).replace("-", "_"))
        if action is None:
            raise UserError(f"--config {path}: unknown key '{key}' (known: {', '.join(sorted(names))})")
        out[action.dest] = _value(action, value, f"--config {path}: key '{key}'")
    return out


def apply_config_file(parser: argparse.ArgumentParser, path: str | Path) -> None:
    """Make the keys of the TOML file ``path`` the defaults of ``parser`` (flags given still win)."""
    parser.set_defaults(**config_defaults(parser, read_config(path), path))


def _chosen_subparser(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The sub-command parser ``args`` came from (``parser`` itself when it has no sub-commands)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            chosen = action.choices.get(getattr(args, action.dest or "", None) or "")
            if chosen is not None:
                return chosen
    return parser


def _repeatable_given(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict[str, Any]:
    """``{dest: values}`` of the repeatable flags given on the command line (their values differ from the default)."""
    given = {}
    for action in parser._actions:
        if isinstance(action, argparse._AppendAction) and getattr(args, action.dest, None) != action.default:
            given[action.dest] = getattr(args, action.dest)
    return given


def parse_args_with_config(
    parser: argparse.ArgumentParser, argv: Sequence[str] | None = None, option: str = "config"
) -> argparse.Namespace:
    """Parse ``argv``; when the chosen (sub-)command got ``--config FILE``, preset it from FILE and parse again.

    Any command that declares ``--config`` gets the behaviour for free; a command without it is parsed once.
    A repeatable flag given on the command line replaces the file's list (argparse alone would append to it).
    A bad file raises ``UserError`` (the caller prints it as one line).
    """
    args = parser.parse_args(argv)
    path = getattr(args, option, None)
    if not path:
        return args
    chosen = _chosen_subparser(parser, args)
    given = _repeatable_given(chosen, args)
    apply_config_file(chosen, path)
    args = parser.parse_args(argv)
    for dest, values in given.items():
        setattr(args, dest, values)
    return args
