"""The paper's Figs. 3-5 for every design: f_hat against the true fault, angle of attack, pitch rate.

Why axis limits from the stable designs only: a design whose loop is unstable (it diverges, or oscillates
at the actuator limit) would otherwise squash every other curve to a flat line; its curve is still drawn,
clipped, and its legend entry says so. Why the legend sits outside the axes and every design has its own
line style and staggered markers: after the fault is compensated several designs lie on the same value,
and a legend box or a solid line on top would hide a trace (the certified one was hidden from k = 62).
Why a design that could not be designed still has a legend entry (no curve): a reader comparing with the
figures in the docs sees that it is missing on purpose, not lost.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from monitor.demo.methods import look
from monitor.demo.montecarlo import Trace

__all__ = ["Panel", "write_figures", "write_identification_figure"]


@dataclass(frozen=True)
class Panel:
    """One of the paper's figures: which series, how it is labelled, and what is written beside it."""

    file: str
    field: str
    ylabel: str
    title: str
    truth: bool = False  # draw the true fault too
    caption: str = ""  # printed under the axes
    reference: float | None = None  # a horizontal line the model predicts
    reference_label: str = ""


def _limits(series: list[np.ndarray], floor: float) -> tuple[float, float]:
    finite = [s[np.isfinite(s)] for s in series]
    finite = [s for s in finite if s.size and np.max(np.abs(s)) < 1e3]
    if not finite:
        return -floor, floor
    lo = min(float(np.min(s)) for s in finite)
    hi = max(float(np.max(s)) for s in finite)
    pad = 0.15 * max(hi - lo, floor)
    return lo - pad, hi + pad


def _panel(
    ax,
    runs: dict[str, Trace],
    panel: Panel,
    onset: int | None,
    title: str,
    unstable: frozenset[str],
    xlabel: bool = True,
    failed: tuple[str, ...] = (),
    h: float = 1.0,
    clipped_note: str = "unstable loop: clipped",
) -> None:
    stable = [getattr(t, panel.field) for name, t in runs.items() if name not in unstable]
    # nothing stable: the fault panel keeps the true fault's scale (the estimate's question is how close to it)
    series = stable or ([] if panel.truth else [getattr(t, panel.field) for t in runs.values()])
    if panel.truth:
        first = next(iter(runs.values()))
        ax.step(np.asarray(first.k) * h, first.f, where="post", color="black", lw=2.0, zorder=2, label="true fault f")
        series.append(first.f)
    if panel.reference is not None:
        ax.axhline(panel.reference, color="black", ls=(0, (1, 3)), lw=1.2, zorder=2, label=panel.reference_label)
        series.append(np.array([panel.reference]))
    lo, hi = _limits(series, 0.5)
    # one design's marker per sample (coincident curves show every design's marks), thinned on long runs
    every = max(3, len(runs), max(len(t.k) for t in runs.values()) // 80)
    for i, (name, t) in enumerate(runs.items()):
        y = getattr(t, panel.field)
        x = np.asarray(t.k) * h  # seconds: what a flight-control engineer reads
        outside = ~np.isfinite(y) | (y < lo) | (y > hi)
        left = bool(np.any(outside))
        faint = name in unstable  # drawn underneath, so the stable designs stay readable
        style = look(name)
        if left:
            # a run that leaves the axes is drawn up to where it leaves them, and that point is marked: clipped
            # on for the rest of the run, a diverging oscillation painted a band over the whole plot
            exit_at = int(np.argmax(outside))
            kept = np.nan_to_num(y[: exit_at + 1], nan=hi, posinf=hi, neginf=lo)
            x, y = x[: exit_at + 1], np.clip(kept, lo, hi)
            ax.plot(x[-1:], y[-1:], marker="x", ms=8, color=style.colour, zorder=4, ls="")
        ax.plot(
            x,
            np.clip(y, lo, hi),
            color=style.colour,
            ls=style.line,
            lw=0.8 if faint else 1.4,
            marker="" if faint else style.marker,
            ms=4,
            markevery=(i % every, every),
            alpha=0.45 if faint else 1.0,
            zorder=1 if faint else 3,
            label=f"{name}{f' ({clipped_note}, leaves the axes at x)' if left else ''}",
        )
    for name in failed:
        style = look(name)
        ax.plot(
            [],
            [],
            color=style.colour,
            ls=style.line,
            marker=style.marker,
            ms=4,
            alpha=0.45,
            label=f"{name} (design failed: not run)",
        )
    if onset is not None:
        ax.axvline(onset * h, color="grey", ls="--", lw=1)
        ax.annotate(
            f"fault onset t = {onset * h:g} s (k = {onset})",
            (onset * h, hi),
            xytext=(4, -14),
            textcoords="offset points",
            fontsize=8,
            color="grey",
        )
    ax.set_ylim(lo, hi)
    if xlabel:
        ax.set_xlabel(f"time t = k h (s), h = {h:g} s")
    ax.set_ylabel(panel.ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    if panel.caption:
        ax.text(
            0.0,
            -0.2 if xlabel else -0.08,
            panel.caption,
            transform=ax.transAxes,
            fontsize=7.5,
            color="dimgrey",
            va="top",
        )
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)


def write_figures(
    runs: dict[str, Trace],
    onset: int | None,
    out_dir: Path,
    subtitle: str,
    unstable: frozenset[str] = frozenset(),
    q_caption: str = "",
    q_steady: float | None = None,
    failed: tuple[str, ...] = (),
    h: float = 1.0,
    paper: bool = True,
    clipped_note: str = "unstable loop: clipped",
) -> list[Path]:
    """Write fig3_fault_estimate.png, fig4_alpha.png, fig5_q.png and an overview; return their paths.

    ``q_caption`` and ``q_steady`` (``monitor.demo.steady.q_caption``) explain Fig. 5's pitch-rate offset;
    ``failed`` names designs that have no run, listed in the legend as such. ``runs`` must not be empty.
    ``paper`` False drops the paper's figure numbers from the titles (the aircraft demo is not in the paper);
    ``clipped_note`` is what the legend says of a faint run whose curve leaves the axes.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = [
        Panel(
            "fig3_fault_estimate.png",
            "f_hat",
            "elevator fault (deg)",
            "Fig. 3: fault estimate f_hat vs true fault",
            truth=True,
        ),
        Panel("fig4_alpha.png", "alpha", "angle of attack alpha (deg)", "Fig. 4: angle of attack after the fault"),
        Panel(
            "fig5_q.png",
            "q",
            "pitch rate q (deg/s)",
            "Fig. 5: pitch rate after the fault",
            caption=q_caption,
            reference=q_steady,
            reference_label="" if q_steady is None else f"model: q with alpha held at 0 ({q_steady:.2f})",
        ),
    ]
    if not paper:
        panels = [replace(p, title=p.title.partition(": ")[2]) for p in panels]
    paths = []
    for panel in panels:
        fig, ax = plt.subplots(figsize=(10, 4.2), dpi=110)
        _panel(
            ax,
            runs,
            panel,
            onset,
            f"{panel.title}\n{subtitle}",
            unstable,
            failed=failed,
            h=h,
            clipped_note=clipped_note,
        )
        path = out_dir / panel.file
        fig.savefig(path, bbox_inches="tight")
        plt.close(fig)
        paths.append(path)
    fig, axes = plt.subplots(len(panels), 1, figsize=(10, 10), dpi=100, sharex=True)
    for i, (ax, panel) in enumerate(zip(axes, panels, strict=True)):
        _panel(
            ax,
            runs,
            panel,
            onset,
            panel.title,
            unstable,
            xlabel=i == len(panels) - 1,
            failed=failed,
            h=h,
            clipped_note=clipped_note,
        )
    fig.suptitle(subtitle, fontsize=9)
    fig.tight_layout()
    path = out_dir / "overview.png"
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    paths.append(path)
    return paths


def _unit_suffix(state: str) -> str:
    """``", deg"`` for a state the contract's sample defines (its unit there), else nothing."""
    from monitor.wire.telemetry import field_of

    try:
        return f", {field_of(state).unit}"
    except KeyError:
        return ""


def write_identification_figure(
    runs: dict[str, dict[str, np.ndarray]],
    names: dict[str, tuple[str, ...]],
    fits: dict[str, dict[str, float]],
    path: Path,
    subtitle: str,
) -> Path:
    """The held-out free runs of each identified model against the flight: one panel per state.

    ``runs`` maps a model's name to its ``validation_run`` (``t``, ``y`` measured, ``y_hat`` simulated from the
    first held-out sample with the flown elevator alone); ``names`` to its states; ``fits`` to fit % per state.
    Why the free run and not one-step predictions: a monitor runs its model for minutes, and a one-step error
    hides the slow modes a short-period model leaves out.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    states = list(dict.fromkeys(s for model in names.values() for s in model))
    fig, axes = plt.subplots(len(states), 1, figsize=(10, 2.4 * len(states)), dpi=100, sharex=True, squeeze=False)
    for ax, state in zip(axes[:, 0], states, strict=True):
        drawn = False
        for model, run in runs.items():
            if state not in names[model]:
                continue
            j = names[model].index(state)
            if not drawn:
                ax.plot(run["t"], run["y"][:, j], color="black", lw=1.6, label="flight (held out)")
                drawn = True
            style = look(model)
            ax.plot(
                run["t"],
                run["y_hat"][:, j],
                color=style.colour,
                ls=style.line,
                lw=1.2,
                label=f"{model} model, fit {fits[model][state]:.1f} %",
            )
        ax.set_ylabel(f"{state} (deviation{_unit_suffix(state)})")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    axes[-1, 0].set_xlabel("time in the flight (s)")
    fig.suptitle(f"Identified models, free run over held-out data\n{subtitle}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, bbox_inches="tight")
    plt.close(fig)
    return path
