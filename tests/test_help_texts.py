"""Every command's --help: it runs, says what the command is for, and shows each default once and truly."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from monitor.cli import COMMANDS

PROGRAMS = [("monitor", [c]) for c in COMMANDS] + [("monitor", []), ("sim_vehicle", []), ("sim_vehicle", ["run"])]


@pytest.mark.parametrize("module, argv", PROGRAMS, ids=lambda v: v if isinstance(v, str) else " ".join(v) or "-")
def test_help_is_there_and_its_defaults_are_not_doubled_or_empty(module, argv):
    proc = subprocess.run([sys.executable, "-m", module, *argv, "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    text = proc.stdout
    assert text.startswith("usage:")
    description = text.split("\n\n")[1] if "\n\n" in text else ""
    assert len(description.split()) >= 5, f"no description under the usage line:\n{text[:400]}"
    for empty in ("(default: None)", "(default: [])", "(default: True)", "(default: False)", "(default: )"):
        assert empty not in text, f"{empty} in the help of {module} {' '.join(argv)}"
    options = re.split(r"\n  (?=-)", text.split("options:", 1)[-1])
    for block in options:
        assert len(re.findall(r"\(default", block)) <= 1, f"default given twice: {block[:160]}"
