"""Every command's --help: it runs, says what the command is for, and shows each default once and truly."""

from __future__ import annotations

import argparse
import re
import subprocess
import sys

import pytest

ENTRY_POINTS = [("monitor", []), ("sim_vehicle", []), ("sim_vehicle", ["run"]), ("monitor", ["design"])]


def _check_help(text: str, what: str) -> None:
    assert text.startswith("usage:")
    description = text.split("\n\n")[1] if "\n\n" in text else ""
    assert len(description.split()) >= 5, f"no description under the usage line:\n{text[:400]}"
    for empty in ("(default: None)", "(default: [])", "(default: True)", "(default: False)", "(default: )"):
        assert empty not in text, f"{empty} in the help of {what}"
    options = re.split(r"\n  (?=-)", text.split("options:", 1)[-1])
    for block in options:
        assert len(re.findall(r"\(default", block)) <= 1, f"default given twice: {block[:160]}"


@pytest.mark.parametrize("module, argv", ENTRY_POINTS, ids=lambda v: v if isinstance(v, str) else " ".join(v) or "-")
def test_help_runs_from_the_entry_points(module, argv):
    """The programs as a user starts them (each other command's help is checked in process, below: same parsers)."""
    proc = subprocess.run([sys.executable, "-m", module, *argv, "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    _check_help(proc.stdout, f"{module} {' '.join(argv)}")


def _parsers():
    """Every (name, parser) of both programs, built in process (the subprocess test above covers the entry points)."""
    from monitor.cli import build_parser as monitor_parser
    from sim_vehicle.cli import build_parser as sim_parser

    for top in (monitor_parser(), sim_parser()):
        yield top.prog, top
        for action in top._subparsers._group_actions:
            yield from ((f"{top.prog} {name}", p) for name, p in action.choices.items())


def _subcommand_lines():
    from monitor.cli import build_parser as monitor_parser
    from sim_vehicle.cli import build_parser as sim_parser

    for top in (monitor_parser(), sim_parser()):
        for action in top._subparsers._group_actions:
            yield from ((top.prog, a.dest, a.help) for a in action._choices_actions)


@pytest.mark.parametrize(
    "prog, name, line", list(_subcommand_lines()), ids=lambda v: v if isinstance(v, str) and " " not in v else ""
)
def test_every_subcommand_says_in_one_line_what_it_is_for(prog, name, line):
    assert line and len(line.split()) >= 6 and len(line) <= 110, f"{prog} {name}: {line!r}"


@pytest.mark.parametrize("name, parser", list(_parsers()), ids=lambda v: v if isinstance(v, str) else "")
def test_every_help_says_what_it_is_for_and_shows_each_default_once(name, parser):
    _check_help(parser.format_help(), name)


@pytest.mark.parametrize("name, parser", list(_parsers()), ids=lambda v: v if isinstance(v, str) else "")
def test_stated_defaults_are_the_real_ones_and_lines_are_wrapped(name, parser):
    text = parser.format_help()
    assert all(len(line) <= 120 for line in text.splitlines()), f"an unwrapped line in {name} --help"
    for action in parser._actions:
        text = (action.help or "") % {**vars(action), "prog": parser.prog}  # as argparse expands it
        stated = re.search(r"\(default: ([^);]*)", text)
        if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
            assert stated is None, f"{name} {action.option_strings}: a switch has no default to state"
            continue
        if stated is None or action.default in (None, argparse.SUPPRESS) or isinstance(action.default, bool):
            continue  # prose defaults ("until a signal", "half the threshold") are read by people
        value = stated.group(1).split()[0].rstrip(",")
        if isinstance(action.default, (int, float)):
            assert float(value) == action.default, f"{name} {action.option_strings}: says {value}, is {action.default}"
        else:
            assert value == str(action.default), f"{name} {action.option_strings}: says {value}, is {action.default}"
