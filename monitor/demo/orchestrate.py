"""The demo's steps in order: gains (cached), independent verdicts, runs, table, figures, summary.json."""

from __future__ import annotations

import json
import sys
import time
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from monitor.demo.live import Scenario
from monitor.demo.methods import METHODS
from monitor.errors import UserError

__all__ = ["DemoOptions", "run_demo"]


@dataclass(frozen=True)
class DemoOptions:
    """What ``fault-monitor demo`` was asked for; ``methods`` is data: any design ``run_design`` knows."""

    scenario: Scenario = field(default_factory=Scenario)
    out: str = "demo-out"
    methods: tuple[str, ...] = METHODS
    runs: int | None = None
    redesign: bool = False
    figures: bool = True


class _Progress:
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


def _gains_for(method: str, plant, path: Path, redesign: bool, progress: _Progress):
    """Load ``path`` when it holds this method's gains for this very plant; otherwise design and write it."""
    from monitor.gains import read_gains, write_gains

    if path.exists() and not redesign:
        try:
            cached = read_gains(path)
            current = cached.method == method and cached.meta.get("plant_hash") == plant.digest and (
                method != "certified" or cached.meta.get("objective") == "fast")  # older files: the H-inf design
            if current:
                progress(f"{method:<15} gains: cached {path}", final=True)
                return cached
        except UserError:
            pass  # unreadable cache: design again
    from monitor.design import run_design

    progress(f"{method:<15} gains: designing ...")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = run_design(method, plant)
    write_gains(path, result, plant)
    progress(f"{method:<15} gains: designed in {result.total_seconds:.1f} s -> {path}", final=True)
    return read_gains(path)


def run_demo(options: DemoOptions) -> int:
    from monitor.demo.report import Row, format_table, row_from_recording
    from monitor.plant import load_plant
    from monitor.verify import verify_gains
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec

    t0 = time.monotonic()
    progress = _Progress()
    opt, scenario = options, options.scenario
    plant = load_plant(scenario.plant)
    if plant.continuous is None:
        raise UserError(f"the demo flies a continuous plant; '{scenario.plant}' is discrete (try paper-continuous)")
    fault = parse_fault_spec(scenario.fault)  # fail early on a bad SPEC, before any daemon starts
    parse_delay_spec(scenario.delay, scenario.seed)
    out = Path(opt.out)
    (out / "gains").mkdir(parents=True, exist_ok=True)
    gains = {m: _gains_for(m, plant, out / "gains" / f"{m}.toml", opt.redesign, progress) for m in opt.methods}
    verdicts = {}
    for m, gf in gains.items():
        v = verify_gains(plant, gf.gains, gf.certificate or None, gf.meta.get("gamma_e"), gf.meta.get("gamma_z"))
        verdicts[m] = v
        progress(f"{m:<15} verify: {'stable' if v.stable else 'UNSTABLE'} (rho_max {v.rho_max:.3f}, "
                 f"time-varying {v.rho_time_varying:.3f})", final=True)
    cert = {m: {True: "valid", False: "invalid", None: "none"}[v.certificate_valid] for m, v in verdicts.items()}
    subtitle = f"{plant.name}, fault {scenario.fault}, delay {scenario.delay} s, wind {scenario.wind}, seed {scenario.seed}"
    if opt.runs:
        return _monte_carlo(opt, plant, gains, verdicts, cert, out, progress, t0)
    from monitor.demo.live import run_live

    rows: list[Row] = []
    traces = {}
    runs = {}
    for m, gf in gains.items():
        live = run_live(m, Path(gf.source), scenario, out, progress)
        progress(f"{m:<15} live: {len(live.estimates)} estimates over Zenoh in {live.wall_seconds:.1f} s, "
                 f"recording {live.rrd}", final=True)
        row, trace = row_from_recording(m, live.rrd, scenario.fault, verdicts[m].stable, cert[m],
                                        float(gf.meta.get("gamma_e", float("nan"))), float(gf.meta.get("gamma_z", float("nan"))))
        rows.append(row)
        traces[m] = trace
        runs[m] = {"rrd": str(live.rrd), "zenoh_estimates": len(live.estimates), "zenoh_truth": len(live.truth),
                   "wall_seconds": round(live.wall_seconds, 2), "sim_exit": live.sim_exit, "monitor_exit": live.monitor_exit}
    figures = []
    if opt.figures:
        from monitor.demo.figures import write_figures
        from monitor.demo.steady import q_caption

        unstable = frozenset(m for m, v in verdicts.items() if not v.stable)
        caption, q_steady = q_caption(plant, fault, scenario.steps)
        figures = [str(p) for p in write_figures(traces, fault.onset, out, subtitle, unstable, caption, q_steady)]
    print(f"\nPaper scenario, live over MAVLink/UDP + Zenoh ({subtitle}; {scenario.steps} samples at {scenario.speedup:g}x)\n")
    print(format_table(rows))
    print("\nFE settling: samples after onset until |f_hat - f| <= 5 % of the fault for good. 2 is the floor, the "
          "earliest possible, not a limit to stay under: the fault first shows in y one sample after onset, so no "
          "observer of form (5) settles sooner. Alarm delay: samples after onset.")
    print(f"Recordings: {', '.join(r['rrd'] for r in runs.values())}  (rerun FILE.rrd | fault-monitor replay FILE.rrd)")
    if figures:
        print(f"Figures:    {', '.join(figures)}")
    summary = {"mode": "live", "options": asdict(opt), "rows": [asdict(r) for r in rows], "runs": runs,
               "figures": figures, "wall_seconds": round(time.monotonic() - t0, 2)}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=_json_default))
    print(f"Summary:    {out / 'summary.json'}  (total {summary['wall_seconds']:.1f} s)")
    return 0


def _monte_carlo(opt: DemoOptions, plant, gains, verdicts, cert, out: Path, progress, t0: float) -> int:
    from monitor.demo.montecarlo import monte_carlo

    sc = opt.scenario
    results = {}
    for m, gf in gains.items():
        progress(f"{m:<15} Monte-Carlo: {opt.runs} runs ...")
        scores = monte_carlo(plant, gf.gains, opt.runs, sc.steps, sc.fault, sc.delay, sc.wind, sc.seed)
        settle = [s.settling_steps for s in scores]
        settled = [s for s in settle if s is not None]
        results[m] = {
            "stable": verdicts[m].stable, "certificate": cert[m], "runs": opt.runs,
            "settled_runs": len(settled),
            "settling_mean": float(np.mean(settled)) if settled else None,
            "settling_worst": (max(settled) if len(settled) == len(settle) else None) if settled else None,
            "rms_ef_mean": float(np.mean([s.rms_ef for s in scores if s.rms_ef is not None])),
            "peak_alpha_worst": float(max(s.peak_alpha_after for s in scores if s.peak_alpha_after is not None)),
        }
        progress(f"{m:<15} Monte-Carlo: done", final=True)
    print(f"\nMonte-Carlo over {opt.runs} delay seeds from {sc.seed} ({plant.name}, fault {sc.fault}, delay {sc.delay} s,"
          f" {sc.steps} samples; simulation only)\n")
    head = f"{'design':<15} {'real loop':<9} {'settled':>8} {'settling mean':>14} {'worst':>6} {'RMS e_f':>9} {'worst |alpha|':>14}"
    print(head)
    print("-" * len(head))
    for m, r in results.items():
        mean = "-" if r["settling_mean"] is None else f"{r['settling_mean']:.2f}"
        worst = "never" if r["settling_worst"] is None else str(r["settling_worst"])
        print(f"{m:<15} {'stable' if r['stable'] else 'UNSTABLE':<9} {r['settled_runs']:>4}/{opt.runs:<3} {mean:>14} "
              f"{worst:>6} {r['rms_ef_mean']:>9.3g} {r['peak_alpha_worst']:>14.3g}")
    summary = {"mode": "monte-carlo", "options": asdict(opt), "results": results,
               "wall_seconds": round(time.monotonic() - t0, 2)}
    (out / "montecarlo.json").write_text(json.dumps(summary, indent=2, default=_json_default))
    print(f"\nResults: {out / 'montecarlo.json'} (the live run's summary.json, if any, is untouched)")
    return 0


def _json_default(value):
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    return str(value)
