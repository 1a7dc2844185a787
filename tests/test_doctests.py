"""Every example in a docstring of monitor/ and sim_vehicle/ runs, and prints what the docstring says.

Why a test and not ``--doctest-modules``: the README's test command is what CI runs, so the examples run there
with the rest; and importing every module this way skips the entry points (``__main__``), which would start a
program.
"""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules_with_examples() -> list[str]:
    names = []
    for py in sorted([*ROOT.joinpath("monitor").rglob("*.py"), *ROOT.joinpath("sim_vehicle").rglob("*.py")]):
        if py.name == "__main__.py" or ">>> " not in py.read_text():
            continue
        names.append(".".join(py.relative_to(ROOT).with_suffix("").parts).removesuffix(".__init__"))
    return names


MODULES = _modules_with_examples()


def test_there_are_examples_to_run() -> None:
    assert len(MODULES) >= 4, MODULES  # the walk above found the modules that have examples


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_of_a_module_hold(name: str) -> None:
    module = importlib.import_module(name)
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = [t for t in finder.find(module) if t.examples]
    assert tests, f"{name} has '>>> ' in its text but no example doctest finds"
    for test in tests:
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed (output above)"
