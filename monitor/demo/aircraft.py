"""``fault-monitor demo --aircraft NAME``: the live comparison on a JSBSim aircraft, beside the paper's scenario.

The steps, each what a user would do with the project's own commands:

1. **An identification flight**: ``sim-vehicle run --aircraft NAME --excite prbs:...`` flies open loop about
   trim, and the demo records what it sends into ``DIR/identification/flight.tlog``, one record per MAVLink
   frame, as a ground station logs it. The flight is kept (and reused while the aircraft, condition, manoeuvre
   and seed stay the same).
2. **Two models from that log**, with ``identify``'s own code: the short-period model (alpha, q: the paper's
   model class) and the longitudinal one (alpha, q, theta, airspeed), written to ``DIR/plants/`` with their
   held-out fit (``DIR/identification.png`` draws the free runs).
3. **Every design for each model** (cached per model in ``DIR/gains/<model>/``), checked by ``verify``.
4. **Every design flown live** on the nonlinear aircraft with the fault and the delay: real ``sim-vehicle``
   and ``fault-monitor run`` daemons on loopback, as in the paper's demo. The rows are scored from the
   recordings; the table adds |e_f| and the alpha hold 30 s after onset, where a model without the phugoid
   has lost the fault.

Why the short-period model is flown too: it is what the paper's method is shown on, and the comparison is the
point. It estimates the fault for a few seconds and then blames the phugoid's slow drift on it.
"""

from __future__ import annotations

import json
import select
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from monitor.demo.live import Aircraft, Daemon, Scenario
from monitor.demo.methods import METHODS
from monitor.errors import UserError
from monitor.wire.specs import Excitation, parse_excite_spec

if TYPE_CHECKING:
    from monitor.demo.orchestrate import Designed, DesignFn, FailedDesign, Flown, Progress
    from monitor.pipelines.identify_log import IdentifiedLog

__all__ = ["MODELS", "LATE_S", "AircraftDemoOptions", "run_aircraft_demo", "record_identification_flight"]

MODELS: tuple[str, ...] = ("short-period", "longitudinal")
LATE_S = 30.0  # s after onset: where the table reads |e_f| and the alpha hold
LEAD_S = 15.0  # s of the identification flight beyond the manoeuvre (trim before it, settling after it)


@dataclass(frozen=True)
class AircraftDemoOptions:
    """What ``fault-monitor demo --aircraft`` was asked for (``scenario.aircraft`` is set)."""

    scenario: Scenario
    excite: str = "prbs:1:60"
    excite_speedup: float = 10.0
    out: str = "demo-aircraft"
    methods: tuple[str, ...] = METHODS
    models: tuple[str, ...] = MODELS
    redesign: bool = False
    figures: bool = True


@dataclass
class _ModelRuns:
    designed: dict[str, Designed] = field(default_factory=dict)
    failed: dict[str, FailedDesign] = field(default_factory=dict)
    flown: dict[str, Flown] = field(default_factory=dict)


def _aircraft(scenario: Scenario) -> Aircraft:
    """The scenario's aircraft: an aircraft demo's scenario always has one."""
    assert scenario.aircraft is not None
    return scenario.aircraft


def _excitation(spec: str) -> Excitation:
    """The manoeuvre, parsed by the vehicle's own reader of ``--excite`` (the demo needs one: not ``none``)."""
    excitation = parse_excite_spec(spec)
    if excitation is None:
        raise UserError(f"--excite '{spec}': the aircraft demo identifies from a manoeuvre, e.g. prbs:1:60")
    return excitation


def record_identification_flight(
    aircraft: Aircraft, excite: str, seed: int, speedup: float, tlog: Path, log_dir: Path, progress: Callable[..., None]
) -> int:
    """Fly the manoeuvre with a real sim-vehicle and log every frame it sends; returns the records written.

    The demo is the ground station here: nothing answers the vehicle (the manoeuvre is open loop), and the
    log's stamps are the wall clock at reception, as MAVProxy writes them.
    """
    from monitor.link.tlog import TlogWriter

    steps = _excitation(excite).samples(1.0 / aircraft.rate) + round(LEAD_S * aircraft.rate)
    tlog.parent.mkdir(parents=True, exist_ok=True)
    log_dir.mkdir(parents=True, exist_ok=True)
    partial = tlog.with_suffix(".partial")
    records = 0
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock, TlogWriter(partial) as writer:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
        sim = Daemon(
            "sim_vehicle",
            [
                "run",
                *aircraft.vehicle_args(),
                "--excite",
                excite,
                "--steps",
                str(steps),
                "--speedup",
                f"{speedup:g}",
                "--seed",
                str(seed),
                "--mavlink",
                f"udpout:127.0.0.1:{port}",
                "--no-zenoh",
                "--log-level",
                "INFO",
            ],
            log_dir / "identification-sim.log",
        )
        deadline = time.monotonic() + steps / aircraft.rate / speedup + 60.0
        try:
            quiet_until = None
            while True:
                ready, _, _ = select.select([sock], [], [], 0.2)
                if ready:
                    data = sock.recv(65535)
                    records += writer.write_datagram(time.time_ns() // 1000, data)
                    if records % 2000 < 4:
                        progress(f"{'identification':<28} flight: {records} frames logged")
                    continue
                if sim.proc.poll() is not None:  # exited: drain what is still in flight, then stop
                    quiet_until = quiet_until or time.monotonic() + 0.5
                    if time.monotonic() > quiet_until:
                        break
                if time.monotonic() > deadline:
                    raise UserError(f"the identification flight did not finish {steps} samples in time")
        finally:
            code = sim.stop()
    if code != 0:
        tail = (log_dir / "identification-sim.log").read_text(errors="replace").strip().splitlines()[-1:]
        raise UserError(f"sim-vehicle --aircraft {aircraft.name} failed (exit {code}): {' '.join(tail)}")
    partial.replace(tlog)
    return records


def _flight_key(opt: AircraftDemoOptions) -> dict:
    """What the identification flight depends on: reuse the recorded one only when all of it is the same."""
    sc = opt.scenario
    return {"aircraft": asdict(_aircraft(sc)), "excite": opt.excite, "seed": sc.seed, "sysid": 1}


def _identification_log(opt: AircraftDemoOptions, progress: Progress) -> Path:
    """The identification flight's tlog: the one recorded before for the same flight, or a new one."""
    d = Path(opt.out) / "identification"
    tlog, key_file = d / "flight.tlog", d / "flight.json"
    key = _flight_key(opt)
    if not opt.redesign and tlog.exists() and key_file.exists():
        try:
            if json.loads(key_file.read_text()) == key:
                progress(f"{'identification':<28} flight: recorded before, {tlog}", final=True)
                return tlog
        except ValueError:
            pass
    t0 = time.monotonic()
    records = record_identification_flight(
        _aircraft(opt.scenario),
        opt.excite,
        opt.scenario.seed,
        opt.excite_speedup,
        tlog,
        Path(opt.out) / "logs",
        progress,
    )
    key_file.write_text(json.dumps(key, indent=2))
    progress(f"{'identification':<28} flight: {records} frames in {time.monotonic() - t0:.1f} s -> {tlog}", final=True)
    return tlog


def _identify_models(opt: AircraftDemoOptions, tlog: Path, progress: Progress) -> dict[str, IdentifiedLog]:
    from monitor.pipelines.identify_log import IdentifyRequest, identify_log

    sc = opt.scenario
    out: dict[str, IdentifiedLog] = {}
    for model in opt.models:
        path = Path(opt.out) / "plants" / f"{_aircraft(sc).name}-{model}.toml"
        done = identify_log(IdentifyRequest(log=str(tlog), out=str(path), model=model))
        fits = ", ".join(f"{s} {f:.1f} %" for s, f in done.result.fit_validation.items())
        progress(f"{model:<28} identified: held-out fit {fits} -> {path}", final=True)
        out[model] = done
    return out


def _fly(
    model: str, d: Designed, scenario: Scenario, trim: tuple[float, float], out: Path, progress: Callable[..., None]
) -> Flown:
    """One design for one model flown live (the paper demo's ``fly_live``), its row with the late window."""
    from monitor.demo.orchestrate import fly_live
    from monitor.demo.report import late_window
    from monitor.wire.specs import parse_fault_spec

    flown = fly_live(d, scenario, out, progress, label=f"{model}-{d.method}", trim=trim)
    flown.row.model = model
    flown.row.ef_late, flown.row.alpha_late = late_window(
        flown.trace, parse_fault_spec(scenario.fault).onset, _aircraft(scenario).rate, LATE_S
    )
    return flown


def run_aircraft_demo(opt: AircraftDemoOptions, design: DesignFn | None = None) -> int:
    """The aircraft demo end to end; returns the exit status (raises a failed ``certified``'s error at the end)."""
    from dataclasses import replace

    from monitor.demo.orchestrate import Progress, conclude, default_design, design_all
    from monitor.model.plant import load_plant
    from monitor.wire.specs import parse_delay_spec, parse_fault_spec

    t0 = time.monotonic()
    progress = Progress()
    parse_fault_spec(opt.scenario.fault)  # fail early on a bad SPEC, before any flight
    parse_delay_spec(opt.scenario.delay, opt.scenario.seed)
    _excitation(opt.excite)
    out = Path(opt.out)
    out.mkdir(parents=True, exist_ok=True)
    tlog = _identification_log(opt, progress)
    identified = _identify_models(opt, tlog, progress)
    runs: dict[str, _ModelRuns] = {}
    for model, ident in identified.items():
        plant = load_plant(str(ident.plant_path))
        r = runs[model] = _ModelRuns()
        r.designed, r.failed = design_all(
            opt.methods, plant, out / "gains" / model, opt.redesign, progress, design or default_design
        )
        scenario = replace(opt.scenario, plant=str(ident.plant_path))
        op = ident.result.operating_point
        trim = (op["alpha"], op["q"])
        r.flown = {m: _fly(model, d, scenario, trim, out, progress) for m, d in r.designed.items()}
    _report(opt, identified, runs, tlog, t0)
    # the exit follows the longitudinal model's certified design: the one a user should fly; conclude warns of
    # that model's failed baselines, the other model's failures are warned of here
    primary = runs.get("longitudinal") or next(iter(runs.values()))
    for model, r in runs.items():
        for m, f in r.failed.items() if r is not primary else ():
            print(f"fault-monitor demo: WARNING: {model}/{m} failed ({f.note})", file=sys.stderr)
    return conclude(opt.methods, primary.failed)


def _report(
    opt: AircraftDemoOptions, identified: dict[str, IdentifiedLog], runs: dict[str, _ModelRuns], tlog: Path, t0: float
) -> None:
    """The table, the figures (per model, and the identification's), and summary.json."""
    from monitor.demo.orchestrate import json_default
    from monitor.demo.report import Row, format_table

    sc = opt.scenario
    ac = _aircraft(sc)
    out = Path(opt.out)
    rows = [
        Row.failed(m, r.failed[m].note, model) if m in r.failed else r.flown[m].row
        for model, r in runs.items()
        for m in opt.methods
    ]
    subtitle = (
        f"{ac.name} at {ac.airspeed:g} kt, {ac.altitude:g} ft, {ac.rate:g} Hz; fault {sc.fault}, "
        f"delay {sc.delay} s, turbulence {ac.turbulence}, seed {sc.seed}"
    )
    figures = _figures(opt, identified, runs, subtitle) if opt.figures else []
    print(f"\nJSBSim {ac.name}, live over MAVLink/UDP + Zenoh ({subtitle}; {sc.steps} samples at {sc.speedup:g}x)\n")
    for model, ident in identified.items():
        res = ident.result
        fits = ", ".join(f"{s} {f:.1f} %" for s, f in res.fit_validation.items())
        modes = "; ".join(m.describe() for m in res.modes)
        print(f"{model:<13} model: held-out fit {fits}; {modes}")
    print()
    print(format_table(rows, LATE_S))
    print(
        f"\nSamples are h = {1 / ac.rate:g} s. |e_f| and alpha {LATE_S:g} s after: means over the second ending "
        f"{LATE_S:g} s after onset (alpha as a deviation from trim). The short-period model (the paper's model class) "
        "leaves out the phugoid (airspeed, pitch angle): its observer reads the aircraft's slow drift off trim as "
        "fault. 'stable' is verify's verdict on the model; a loop with little margin there may not settle on the "
        "aircraft, whose dynamics the model only approximates."
    )
    print(f"Identification flight: {tlog}  Plants: {', '.join(str(i.plant_path) for i in identified.values())}")
    recordings = [f.run["rrd"] for r in runs.values() for f in r.flown.values()]
    if recordings:
        print(f"Recordings: {', '.join(recordings)}")
    if figures:
        print(f"Figures:    {', '.join(figures)}")
    summary = {
        "mode": "aircraft",
        "options": asdict(opt),
        "rows": [asdict(r) for r in rows],
        "identification": {m: {"plant": str(i.plant_path), **i.report()} for m, i in identified.items()},
        "runs": {f"{model}/{m}": f.run for model, r in runs.items() for m, f in r.flown.items()},
        "figures": figures,
        "late_window_s": LATE_S,
        "wall_seconds": round(time.monotonic() - t0, 2),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=json_default))
    print(f"Summary:    {out / 'summary.json'}  (total {summary['wall_seconds']:.1f} s)")


def _lost(flown: Flown) -> bool:
    """A run drawn faint, as an unstable one: unstable on the model, or stable there but with an estimate
    error on the aircraft larger than the fault itself. Its excursions would otherwise set the axes and
    flatten every curve that follows the fault."""
    row, fault = flown.row, float(np.max(np.abs(flown.trace.f))) if flown.trace.f.size else 0.0
    return not row.stable or row.rms_ef is None or not row.rms_ef <= max(fault, 1e-9)


def _figures(
    opt: AircraftDemoOptions, identified: dict[str, IdentifiedLog], runs: dict[str, _ModelRuns], subtitle: str
) -> list[str]:
    from monitor.demo.figures import write_figures, write_identification_figure
    from monitor.wire.specs import parse_fault_spec

    out = Path(opt.out)
    onset = parse_fault_spec(opt.scenario.fault).onset
    h = 1 / _aircraft(opt.scenario).rate
    paths = [
        write_identification_figure(
            {m: i.result.validation_run for m, i in identified.items()},
            {m: i.result.state_names for m, i in identified.items()},
            {m: i.result.fit_validation for m, i in identified.items()},
            out / "identification.png",
            subtitle,
        )
    ]
    for model, r in runs.items():
        if not r.flown:
            continue
        d = out / model
        d.mkdir(parents=True, exist_ok=True)
        faint = frozenset(m for m, f in r.flown.items() if _lost(f))
        paths += write_figures(
            {m: f.trace for m, f in r.flown.items()},
            onset,
            d,
            f"{model} model; {subtitle}",
            faint,
            failed=tuple(r.failed),
            h=h,
            paper=False,
            clipped_note="lost on the aircraft: clipped",
        )
    return [str(p) for p in paths]
