"""A single-point check run at every point of an envelope (``threshold`` and ``detectability`` on an envelope plant).

Each point is checked alone, with its own plant and its own gains, exactly as the single-point command checks
it; a point's failure is the command's one-line error with the point named. The envelope's answer is its worst
point: the largest figure (a proven threshold, a smallest detectable bias). Switching between the points is what
``verify``'s common certificate covers; these figures hold while the vehicle stays at a point.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

from monitor.errors import UserError
from monitor.gains import GainsFile
from monitor.model.plant import Plant

__all__ = ["each_point", "worst_point"]

T = TypeVar("T")


def each_point(
    points: Sequence[tuple[str, Plant, GainsFile]], check: Callable[[Plant, GainsFile], T]
) -> list[tuple[str, T]]:
    """``check(plant, gains)`` at every ``(name, plant, gains)`` in order; a ``UserError`` names its point."""
    results: list[tuple[str, T]] = []
    for name, plant, gains in points:
        try:
            results.append((name, check(plant, gains)))
        except UserError as exc:
            error = UserError(f"point '{name}': {exc}")
            error.exit_code = exc.exit_code  # the single-point command's exit code
            raise error from None
    return results


def worst_point(results: Sequence[tuple[str, T]], figure: Callable[[T], float]) -> tuple[str, T]:
    """The point with the largest ``figure`` (the first of equals); an infinite figure (undetectable) is the worst."""
    if not results:
        raise ValueError("no points")
    return max(results, key=lambda row: figure(row[1]))
