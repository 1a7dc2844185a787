"""The demo's steps in order: gains (cached), independent verdicts, runs, table, figures, summary.json.

Why a design that fails does not stop the demo: the baselines are there to be compared with, and an LMI
solver that answers ``optimal_inaccurate`` for one of them on some machine must not take the comparison of
the others with it. A failed design is carried through as a ``FailedDesign`` (no verdict, no run, no
Monte-Carlo), its row says ``design failed: <reason>``, and the exit status is nonzero only when the
project's own design, ``certified``, fails (or nothing at all could be designed): then the demo has
nothing left to show, and the error is the one ``fault-monitor design`` would report, with its exit code.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from monitor.demo.live import Scenario
from monitor.demo.methods import METHODS
from monitor.errors import UserError

if TYPE_CHECKING:
    from monitor.demo.montecarlo import Trace
    from monitor.demo.report import Row
    from monitor.design.result import DesignResult
    from monitor.gains import GainsFile
    from monitor.model.plant import Plant

__all__ = [
    "PRIMARY",
    "DemoOptions",
    "Designed",
    "FailedDesign",
    "Flown",
    "Progress",
    "run_demo",
    "design_all",
    "default_design",
    "fly_live",
    "report_live",
    "conclude",
    "json_default",
]

PRIMARY = "certified"  # the project's own design: the demo fails when (and only when) this one cannot be designed

DesignFn = Callable[[str, "Plant"], "DesignResult"]


@dataclass(frozen=True)
class DemoOptions:
    """What ``fault-monitor demo`` was asked for; ``methods`` is data: any design ``run_design`` knows."""

    scenario: Scenario = field(default_factory=Scenario)
    out: str = "demo-out"
    methods: tuple[str, ...] = METHODS
    runs: int | None = None
    redesign: bool = False
    figures: bool = True


@dataclass(frozen=True)
class FailedDesign:
    """A design that produced no gains; ``error`` is kept whole so that a failed ``certified`` exits as before."""

    method: str
    error: UserError

    @property
    def note(self) -> str:
        """``design failed: <reason>`` on one line: it is a table cell and a JSON string."""
        return "design failed: " + " ".join(str(self.error).split())


@dataclass(frozen=True)
class Designed:
    """A design with gains and ``verify``'s independent verdict: what a run needs and what its row starts from."""

    method: str
    gains: GainsFile
    stable: bool
    certificate: str  # valid, invalid or none

    def claim(self, name: str) -> float:
        """The bound the design claims (``gamma_e``, ``gamma_z``); nan when the gains file records none."""
        return float(self.gains.meta.get(name, float("nan")))


@dataclass
class Flown:
    """One design's run: its row of the table, its trace for the figures, and its bookkeeping for summary.json."""

    row: Row
    trace: Trace
    run: dict


Fly = Callable[[Designed, Scenario, Path, Callable[..., None]], Flown]


class Progress:
    """One status line on stderr, rewritten in place on a terminal, plain lines (throttled) otherwise."""

    def __init__(self) -> None:
        self.tty = sys.stderr.isatty()
        self.last = 0.0

    def __call__(self, text: str, final: bool = False) -> None:
        now = time.monotonic()
        if self.tty:
            sys.stderr.write("\r\033[K" + text + ("\n" if final else ""))
            sys.stderr.flush()
        elif final or now - self.last > 2.0:
            print(text, file=sys.stderr, flush=True)
            self.last = now


def _cached_gains(method: str, plant: Plant, path: Path) -> GainsFile | None:
    """``path`` when it holds this method's gains for this very plant, else None (absent, stale or unreadable)."""
    from monitor.gains import read_gains

    if not path.exists():
        return None
    try:
        cached = read_gains(path)
    except UserError:
        return None  # unreadable cache: design again
    current = (
        cached.method == method
        and cached.meta.get("plant_hash") == plant.digest
        and (method != "certified" or cached.meta.get("objective") == "fast")
    )  # older files: the H-inf design
    return cached if current else None


def _gains_for(
    method: str, plant: Plant, path: Path, redesign: bool, progress: Progress, design: DesignFn
) -> GainsFile | FailedDesign:
    """Load the cached gains or design and write them; a design that raises a ``UserError`` is a ``FailedDesign``.

    Only the design call is guarded: a gains file that cannot be written is the user's to fix, not a result.
    """
    from monitor.gains import read_gains, write_gains

    cached = None if redesign else _cached_gains(method, plant, path)
    if cached is not None:
        progress(f"{method:<15} gains: cached {path}", final=True)
        return cached
    progress(f"{method:<15} gains: designing ...")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            result = design(method, plant)
    except UserError as exc:  # DesignFailed (infeasible, inaccurate) or any other refusal of this design
        failure = FailedDesign(method, exc)
        progress(f"{method:<15} gains: {failure.note}", final=True)
        return failure
    write_gains(path, result, plant)
    progress(f"{method:<15} gains: designed in {result.total_seconds:.1f} s -> {path}", final=True)
    return read_gains(path)


def _verified(method: str, gf: GainsFile, plant: Plant, progress: Progress) -> Designed:
    """``verify``'s verdict on one design's gains, re-checking its certificate when the file carries one."""
    from monitor.checks.verify import verify_gains

    v = verify_gains(plant, gf.gains, gf.certificate or None, gf.meta.get("gamma_e"), gf.meta.get("gamma_z"))
    progress(
        f"{method:<15} verify: {'stable' if v.stable else 'UNSTABLE'} (rho_max {v.rho_max:.3f}, "
        f"time-varying {v.rho_time_varying:.3f})",
        final=True,
    )
    certificate = {True: "valid", False: "invalid", None: "none"}[v.certificate_valid]
    return Designed(method, gf, v.stable, certificate)


def design_all(
    methods: tuple[str, ...], plant: Plant, gains_dir: Path, redesign: bool, progress: Progress, design: DesignFn
) -> tuple[dict[str, Designed], dict[str, FailedDesign]]:
    """Every requested design, verified, and the ones that could not be designed; both in ``methods``' order."""
    gains_dir.mkdir(parents=True, exist_ok=True)
    outcomes = {m: _gains_for(m, plant, gains_dir / f"{m}.toml", redesign, progress, design) for m in methods}
    failed = {m: o for m, o in outcomes.items() if isinstance(o, FailedDesign)}
    designed = {m: _verified(m, o, plant, progress) for m, o in outcomes.items() if not isinstance(o, FailedDesign)}
    return designed, failed


def default_design(method: str, plant: Plant) -> DesignResult:
    """``run_design``, imported only when a design is needed (cvxpy's import costs about a second)."""
    from monitor.design import run_design

    return run_design(method, plant)


def run_demo(options: DemoOptions, design: DesignFn | None = None, fly: Fly | None = None) -> int:
    """The demo end to end; returns the exit status, or raises a failed ``certified`` design's error at the end.

    ``design`` (method, plant -> DesignResult) and ``fly`` (one verified design -> its row and trace) default to
    ``run_design`` and the live daemons; they are parameters so that the steps around them can be exercised alone.
    """
    from monitor.model.plant import load_plant
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec

    t0 = time.monotonic()
    progress = Progress()
    scenario = options.scenario
    plant = load_plant(scenario.plant)
    if plant.continuous is None:
        raise UserError(f"the demo flies a continuous plant; '{scenario.plant}' is discrete (try paper-continuous)")
    parse_fault_spec(scenario.fault)  # fail early on a bad SPEC, before any design or daemon starts
    parse_delay_spec(scenario.delay, scenario.seed)
    designed, failed = design_all(
        options.methods, plant, Path(options.out) / "gains", options.redesign, progress, design or default_design
    )
    if options.runs:
        _monte_carlo(options, plant, designed, failed, progress, t0)
    else:
        flown = {m: (fly or fly_live)(d, scenario, Path(options.out), progress) for m, d in designed.items()}
        report_live(options, plant, flown, failed, t0)
    return conclude(options.methods, failed)


def fly_live(
    designed: Designed,
    scenario: Scenario,
    out: Path,
    progress: Callable[..., None],
    label: str | None = None,
    trim: tuple[float, float] = (0.0, 0.0),
) -> Flown:
    """Fly one design with the real daemons; its row is scored from the recording, as ``replay`` would.

    ``label`` names the run's files (default: the method); ``trim`` (alpha0, q0) turns the recorded, absolute
    alpha and q into deviations (a plant identified about a trim).
    """
    from monitor.demo.live import run_live
    from monitor.demo.report import row_from_recording

    m = designed.method
    name = label or m
    live = run_live(name, Path(designed.gains.source), scenario, out, progress)
    progress(
        f"{name:<15} live: {len(live.estimates)} estimates over Zenoh in {live.wall_seconds:.1f} s, "
        f"recording {live.rrd}",
        final=True,
    )
    row, trace = row_from_recording(
        m,
        live.rrd,
        scenario.fault,
        designed.stable,
        designed.certificate,
        designed.claim("gamma_e"),
        designed.claim("gamma_z"),
        trim,
    )
    run = {
        "rrd": str(live.rrd),
        "zenoh_estimates": len(live.estimates),
        "zenoh_truth": len(live.truth),
        "wall_seconds": round(live.wall_seconds, 2),
        "sim_exit": live.sim_exit,
        "monitor_exit": live.monitor_exit,
    }
    return Flown(row, trace, run)


def _table_rows(methods: tuple[str, ...], flown: dict[str, Flown], failed: dict[str, FailedDesign]) -> list[Row]:
    """One row per requested design, in the order asked for: the run's, or the one saying why there was none."""
    from monitor.demo.report import Row

    return [Row.failed(m, failed[m].note) if m in failed else flown[m].row for m in methods]


def _figures(
    opt: DemoOptions, plant: Plant, flown: dict[str, Flown], failed: dict[str, FailedDesign], subtitle: str
) -> list[str]:
    """The paper's Figs. 3-5 and the overview for the designs that ran; none when nothing ran or none were asked."""
    if not opt.figures or not flown:
        return []
    from monitor.demo.figures import write_figures
    from monitor.demo.steady import q_caption
    from monitor.wire.specs import parse_fault_spec

    fault = parse_fault_spec(opt.scenario.fault)
    unstable = frozenset(m for m, f in flown.items() if not f.row.stable)
    caption, q_steady = q_caption(plant, fault, opt.scenario.steps)
    traces = {m: f.trace for m, f in flown.items()}
    paths = write_figures(traces, fault.onset, Path(opt.out), subtitle, unstable, caption, q_steady, tuple(failed))
    return [str(p) for p in paths]


def _failed_lines(failed: dict[str, FailedDesign]) -> list[str]:
    """The closing lines naming each design that could not be designed, aligned with the other closing lines."""
    return [f"Failed:     {f.method} (no gains, no verdict, no run): {f.note}" for f in failed.values()]


def report_live(
    opt: DemoOptions, plant: Plant, flown: dict[str, Flown], failed: dict[str, FailedDesign], t0: float
) -> dict:
    """Print the table, write the figures and summary.json, and return the summary (``conclude`` has the exit)."""
    from monitor.demo.report import format_table

    sc = opt.scenario
    subtitle = f"{plant.name}, fault {sc.fault}, delay {sc.delay} s, wind {sc.wind}, seed {sc.seed}"
    rows = _table_rows(opt.methods, flown, failed)
    figures = _figures(opt, plant, flown, failed, subtitle)
    print(f"\nPaper scenario, live over MAVLink/UDP + Zenoh ({subtitle}; {sc.steps} samples at {sc.speedup:g}x)\n")
    print(format_table(rows))
    print(
        "\nFE settling: samples after onset until |f_hat - f| <= 5 % of the fault for good. 2 is the floor, the "
        "earliest possible, not a limit to stay under: the fault first shows in y one sample after onset, so no "
        "observer of form (5) settles sooner. Alarm delay: samples after onset."
    )
    runs = {m: f.run for m, f in flown.items()}
    recordings = [r["rrd"] for r in runs.values() if "rrd" in r]
    if recordings:
        print(f"Recordings: {', '.join(recordings)}  (rerun FILE.rrd | fault-monitor replay FILE.rrd)")
    if figures:
        print(f"Figures:    {', '.join(figures)}")
    for line in _failed_lines(failed):
        print(line)
    out = Path(opt.out)
    summary = {
        "mode": "live",
        "options": asdict(opt),
        "rows": [asdict(r) for r in rows],
        "runs": runs,
        "figures": figures,
        "wall_seconds": round(time.monotonic() - t0, 2),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=json_default))
    print(f"Summary:    {out / 'summary.json'}  (total {summary['wall_seconds']:.1f} s)")
    return summary


def conclude(methods: tuple[str, ...], failed: dict[str, FailedDesign]) -> int:
    """The exit status once everything that could be written is written.

    A failed baseline is a WARNING and exit 0: the comparison stands without it. A failed ``certified`` design,
    or no design at all, re-raises the design's own error, so the CLI prints the line and exit code
    (3 for ``DesignFailed``) that ``fault-monitor design`` gives.
    """
    for f in failed.values():
        if f.method != PRIMARY:
            print(
                f"fault-monitor demo: WARNING: the {f.method} baseline failed ({f.note}); the other designs ran",
                file=sys.stderr,
            )
    if PRIMARY in failed:
        raise failed[PRIMARY].error
    if failed and len(failed) == len(methods):
        raise next(iter(failed.values())).error  # nothing was designed, so nothing was compared
    return 0


def _mc_result(opt: DemoOptions, plant: Plant, d: Designed) -> dict:
    """One design's Monte-Carlo over ``opt.runs`` delay seeds, summarised for the table and montecarlo.json."""
    from monitor.demo.montecarlo import monte_carlo

    sc = opt.scenario
    assert opt.runs is not None  # demo --runs N
    scores = monte_carlo(plant, d.gains.gains, opt.runs, sc.steps, sc.fault, sc.delay, sc.wind, sc.seed)
    settle = [s.settling_steps for s in scores]
    settled = [s for s in settle if s is not None]
    return {
        "stable": d.stable,
        "certificate": d.certificate,
        "runs": opt.runs,
        "settled_runs": len(settled),
        "settling_mean": float(np.mean(settled)) if settled else None,
        "settling_worst": (max(settled) if len(settled) == len(settle) else None) if settled else None,
        "rms_ef_mean": float(np.mean([s.rms_ef for s in scores if s.rms_ef is not None])),
        "peak_alpha_worst": float(max(s.peak_alpha_after for s in scores if s.peak_alpha_after is not None)),
    }


def _mc_line(method: str, r: dict, runs: int) -> str:
    """One line of the Monte-Carlo table; a design that failed says so instead of its figures."""
    if "failure" in r:
        return f"{method:<15} {r['failure']}"
    mean = "-" if r["settling_mean"] is None else f"{r['settling_mean']:.2f}"
    worst = "never" if r["settling_worst"] is None else str(r["settling_worst"])
    return (
        f"{method:<15} {'stable' if r['stable'] else 'UNSTABLE':<9} {r['settled_runs']:>4}/{runs:<3} {mean:>14} "
        f"{worst:>6} {r['rms_ef_mean']:>9.3g} {r['peak_alpha_worst']:>14.3g}"
    )


def _monte_carlo(
    opt: DemoOptions,
    plant: Plant,
    designed: dict[str, Designed],
    failed: dict[str, FailedDesign],
    progress: Progress,
    t0: float,
) -> None:
    """The simulation-only comparison over delay seeds, written to montecarlo.json (summary.json is left alone)."""
    sc = opt.scenario
    runs = opt.runs
    assert runs is not None  # demo --runs N
    results = {}
    for m in opt.methods:
        if m in failed:
            results[m] = {"failure": failed[m].note}
            continue
        progress(f"{m:<15} Monte-Carlo: {opt.runs} runs ...")
        results[m] = _mc_result(opt, plant, designed[m])
        progress(f"{m:<15} Monte-Carlo: done", final=True)
    print(
        f"\nMonte-Carlo over {opt.runs} delay seeds from {sc.seed} ({plant.name}, fault {sc.fault}, delay {sc.delay} s,"
        f" {sc.steps} samples; simulation only)\n"
    )
    head = (
        f"{'design':<15} {'real loop':<9} {'settled':>8} {'settling mean':>14} {'worst':>6} {'RMS e_f':>9} "
        f"{'worst |alpha|':>14}"
    )
    print(head)
    print("-" * len(head))
    for m, r in results.items():
        print(_mc_line(m, r, runs))
    out = Path(opt.out)
    summary = {
        "mode": "monte-carlo",
        "options": asdict(opt),
        "results": results,
        "wall_seconds": round(time.monotonic() - t0, 2),
    }
    (out / "montecarlo.json").write_text(json.dumps(summary, indent=2, default=json_default))
    for line in _failed_lines(failed):
        print(line)
    print(f"\nResults: {out / 'montecarlo.json'} (the live run's summary.json, if any, is untouched)")


def json_default(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    return str(value)
