"""Which designs the demo compares, in table order, and how each is drawn.

Why a module of its own: ``fault-monitor demo --help`` (which must stay instant, no numpy), the demo's
options and the figures all need the same list. Adding a design to the demo is one line in ``METHODS``
(plus, optionally, its look in ``LOOKS``; a design without one gets a distinct fallback look).
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["METHODS", "Look", "look"]

METHODS: tuple[str, ...] = ("certified", "robust-separate", "paper", "separate")


class Look(NamedTuple):
    """Colour, line style and marker: distinct styles keep curves that lie on top of each other visible."""

    colour: str
    line: str | tuple[int, tuple[int, ...]]  # a matplotlib line style
    marker: str


LOOKS: dict[str, Look] = {
    "certified": Look("tab:blue", "-", "o"),
    "robust-separate": Look("tab:green", "--", "s"),
    "paper": Look("tab:orange", "-.", "^"),
    "separate": Look("tab:red", ":", "x"),
}
_SPARE = (
    Look("tab:purple", (0, (5, 1, 1, 1)), "D"),
    Look("tab:brown", (0, (1, 1)), "v"),
    Look("tab:pink", (0, (8, 2)), "P"),
    Look("tab:olive", (0, (3, 1, 1, 1, 1, 1)), "*"),
)


def look(name: str) -> Look:
    """The look of design ``name``; unknown names get a spare look chosen from the name, stable across runs."""
    if name in LOOKS:
        return LOOKS[name]
    return _SPARE[sum(name.encode()) % len(_SPARE)]
