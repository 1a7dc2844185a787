"""A Griffe extension for the API reference: the docstrings' doctest examples (``>>>`` lines and their output)
become fenced ``pycon`` blocks, since Markdown would read a bare ``>>>`` as nested quotes. The docstrings stay
plain doctests in the code (tests/test_doctests.py runs them); only their rendering changes.
"""

from __future__ import annotations

from typing import Any

import griffe


def fence_doctests(text: str) -> str:
    """Each run of doctest lines (a ``>>>`` line, its ``...`` continuations and its output up to the next blank
    line) wrapped in a ``pycon`` fence, at the run's own indentation."""
    out: list[str] = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        stripped = lines[i].lstrip()
        if not stripped.startswith(">>>"):
            out.append(lines[i])
            i += 1
            continue
        indent = lines[i][: len(lines[i]) - len(stripped)]
        run = []
        while i < len(lines) and lines[i].strip():
            run.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i].lstrip())
            i += 1
        if out and out[-1].strip():
            out.append("")
        out += [f"{indent}```pycon", *(indent + r for r in run), f"{indent}```"]
    return "\n".join(out)


class DoctestFences(griffe.Extension):
    def on_object(self, *, obj: griffe.Object, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        if obj.docstring is not None and ">>>" in obj.docstring.value:
            obj.docstring.value = fence_doctests(obj.docstring.value)
