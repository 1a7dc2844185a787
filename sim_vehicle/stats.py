"""Counters of one run and the summary printed on exit (and optionally written as JSON)."""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

__all__ = ["RunStats", "delay_stats"]


def delay_stats(values: list[float]) -> dict[str, float | int | None]:
    """count, mean, std, min, p50, p95, max of a list of delays (None entries when empty)."""
    if not values:
        return {"count": 0, "mean": None, "std": None, "min": None, "p50": None, "p95": None, "max": None}
    a = np.asarray(values, dtype=float)
    return {
        "count": int(a.size),
        "mean": float(a.mean()),
        "std": float(a.std()),
        "min": float(a.min()),
        "p50": float(np.percentile(a, 50)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }


@dataclass
class RunStats:
    """Everything the vehicle counts. ``samples``: per-sample outcomes; ``commands``/``packets``: per datagram."""

    samples: Counter = field(default_factory=Counter)
    commands: Counter = field(default_factory=Counter)
    packets: Counter = field(default_factory=Counter)
    tau: list[float] = field(default_factory=list)
    tau_drawn: list[float] = field(default_factory=list)

    def as_dict(self) -> dict:
        return {
            "samples": dict(self.samples),
            "commands": dict(self.commands),
            "packets": dict(self.packets),
            "tau": delay_stats(self.tau),
            "tau_drawn": delay_stats(self.tau_drawn),
        }

    def summary(self) -> str:
        """A short human-readable report."""
        s, c, p = self.samples, self.commands, self.packets

        def fmt(stats: dict) -> str:
            if not stats["count"]:
                return "none"
            return (
                "n={count} mean={mean:.4f} std={std:.4f} min={min:.4f} p50={p50:.4f} p95={p95:.4f} max={max:.4f} s"
            ).format(**stats)

        lines = [
            "sim-vehicle summary",
            f"  samples: taken {s['taken']}, sent {s['sent']}, dropped by link {s['dropped']}, "
            f"duplicated {s['duplicated']}, reordered {s['reordered']}",
            f"  per sample: answered in time {s['applied']}, late {s['late']}, lost (never answered) {s['lost']}, "
            f"flown on board (autopilot/excitation) {s['onboard']}",
            f"  commands: received {c['received']}, applied {c['applied']}, late {c['late']}, "
            f"stale/duplicate {c['stale']}, dropped by link {c['dropped']}, for a future sample {c['future']}, "
            f"other system {c['foreign_target']}, ignored while flying on board (autopilot/excitation) "
            f"{c['ignored_autopilot'] + c['ignored_excitation']}",
            f"  packets: rejected by signing {p['rejected_signature']}, garbage {p['garbage']}, "
            f"truncated {p['truncated']}, other messages {p['other']}, send errors {p['send_errors']}",
            f"  tau (true, applied commands): {fmt(delay_stats(self.tau))}",
            f"  tau drawn from the delay SPEC:  {fmt(delay_stats(self.tau_drawn))}",
        ]
        return "\n".join(lines)
