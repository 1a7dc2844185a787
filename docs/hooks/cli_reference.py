"""mkdocs hook: the parts of the reference that the code defines, generated at build time from the code itself.

A page asks for them with an HTML comment on a line of its own, which this hook replaces:

    <!-- cli: fault-monitor -->          the program's help, then every sub-command's, each under a heading of its
    <!-- cli: sim-vehicle -->            own (a sub-command added to the parser appears without editing a page)
    <!-- cli: fault-monitor design -->   one sub-command's help alone
    <!-- mavlink: sample-fields -->      the table of a sample's MAVLink fields (monitor.wire.telemetry.SAMPLE_FIELDS)

The help is each program's own ``build_parser()`` (``monitor.cli``, ``sim_vehicle.cli``), formatted at a fixed
width, so the reference is the parser and cannot drift from it. A placeholder naming a program or a sub-command
that does not exist stops the build.
"""

from __future__ import annotations

import argparse
import importlib
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager

from mkdocs.exceptions import PluginError

PROGRAMS = {"fault-monitor": "monitor.cli", "sim-vehicle": "sim_vehicle.cli"}
WIDTH = 100  # the help's columns (argparse reads $COLUMNS): wide enough for the flags, narrow enough for a page

_CLI = re.compile(r"^<!--\s*cli:\s*(?P<prog>[\w-]+)(?:\s+(?P<sub>[\w-]+))?\s*-->\s*$", re.M)
_MAVLINK = re.compile(r"^<!--\s*mavlink:\s*sample-fields\s*-->\s*$", re.M)


@contextmanager
def _columns(width: int) -> Iterator[None]:
    before = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(width)
    try:
        yield
    finally:
        if before is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = before


def _parser(prog: str) -> argparse.ArgumentParser:
    if prog not in PROGRAMS:
        raise PluginError(f"cli reference: no program '{prog}' (known: {', '.join(PROGRAMS)})")
    return importlib.import_module(PROGRAMS[prog]).build_parser()


def _subcommands(parser: argparse.ArgumentParser) -> tuple[dict[str, argparse.ArgumentParser], dict[str, str]]:
    """The sub-parsers in the order they were added, and each one's one-line help."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            summaries = {a.dest: a.help or "" for a in action._choices_actions}
            return dict(action.choices), summaries
    return {}, {}


def _help(parser: argparse.ArgumentParser) -> str:
    with _columns(WIDTH):
        text = parser.format_help()
    return "```text\n" + text.rstrip() + "\n```\n"


def cli_markdown(prog: str, sub: str | None = None) -> str:
    """The Markdown that replaces ``<!-- cli: PROG [SUB] -->``."""
    parser = _parser(prog)
    subs, summaries = _subcommands(parser)
    if sub is not None:
        if sub not in subs:
            raise PluginError(f"cli reference: '{prog}' has no sub-command '{sub}' (it has: {', '.join(subs)})")
        return _help(subs[sub])
    parts = [_help(parser)]
    for name, subparser in subs.items():
        summary = summaries.get(name, "")
        parts.append(f"## `{prog} {name}`\n\n" + (f"{summary[0].upper()}{summary[1:]}.\n\n" if summary else ""))
        parts.append(_help(subparser))
    return "\n".join(parts)


def sample_fields_markdown() -> str:
    """``SAMPLE_FIELDS`` as a table: what each quantity of a sample is on the wire."""
    from monitor.wire.telemetry import INSTANT_MESSAGE, SAMPLE_FIELDS

    rows = [
        "| quantity | MAVLink field | wire value × scale = plant value | plant unit | accepted range |",
        "|---|---|---|---|---|",
    ]
    for f in SAMPLE_FIELDS:
        rows.append(f"| `{f.name}` | `{f.ref}` | × {f.scale:.10g} | {f.unit} | {f.range[0]:g} … {f.range[1]:g} |")
    note = (
        f"\nThe sample's instant is `{INSTANT_MESSAGE}.time_usec` (k·h in microseconds). Generated from "
        "`monitor.wire.telemetry.SAMPLE_FIELDS` when the site is built.\n"
    )
    return "\n".join(rows) + "\n" + note


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = _CLI.sub(lambda m: cli_markdown(m.group("prog"), m.group("sub")), markdown)
    return _MAVLINK.sub(lambda _m: sample_fields_markdown(), markdown)
