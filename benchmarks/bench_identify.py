"""Benchmark of ``fault-monitor identify`` on a 60-s and a 10-min flight log (run by hand; prints figures).

Each flight is the c172p of ``tests/c172p_flights.py``, flown by JSBSim at 120 Hz with an elevator PRBS of
+-1 deg (after 5 s of trim) and logged at 20 Hz the way MAVProxy logs (one MAVLink 2 frame per record: ATTITUDE,
AOA_SSA, VFR_HUD, ACTUATOR_OUTPUT_STATUS, a HEARTBEAT a second). It times the whole command
(``python -m monitor identify``, imports included) and, in process, the log reading and the maths separately.

    /work/venv/bin/python benchmarks/bench_identify.py [--minutes 1 10] [--repeat 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.c172p_flights import fly, write_tlog  # noqa: E402 - found through the sys.path entry above


def in_process(log: Path) -> tuple[float, float, int]:
    """(seconds reading the log, seconds identifying, samples) without the interpreter start and imports."""
    import tomllib

    import numpy as np

    from monitor.link.flight_log import log_spacing, read_flight
    from monitor.model.identification import MODELS, FlightData, identify
    from monitor.pipelines.identify_log import IDENTIFY_SIGNALS_TOML, map_for

    states = MODELS["longitudinal"]
    smap, _written = map_for(tomllib.loads(IDENTIFY_SIGNALS_TOML)["signals"], "default", states)
    t = time.perf_counter()
    h = log_spacing(str(log), smap.instant, None)
    flight = read_flight(str(log), smap, h)
    rows = flight.samples[1]
    t_read = time.perf_counter() - t
    t = time.perf_counter()
    k = np.array([r[0] for r in rows])
    X = np.array([[v[s] for s in states] for _k, v in rows])
    U = np.array([[v["elevator"]] for _k, v in rows])
    identify(FlightData(h, k, X, U, states))
    return t_read, time.perf_counter() - t, len(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-identify-"))
    for minutes in args.minutes:
        log = work / f"flight-{minutes:g}min.tlog"
        t = time.perf_counter()
        write_tlog(log, fly(seconds=60.0 * minutes, lead_in=5.0))
        made = time.perf_counter() - t
        walls, report = [], {}
        for _ in range(args.repeat):
            t = time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-m", "monitor", "identify", str(log), "--out", str(work / "plant.toml"), "--json"],
                capture_output=True,
                text=True,
                cwd=REPO,
            )
            walls.append(time.perf_counter() - t)
            if proc.returncode != 0:
                sys.exit(f"identify failed: {proc.stderr.strip()}")
            report = json.loads(proc.stdout)
        reads, fits = [], []
        for _ in range(args.repeat):
            t_read, t_fit, samples = in_process(log)
            reads.append(t_read)
            fits.append(t_fit)
        fit = ", ".join(f"{s} {f:.1f} %" for s, f in report["fit_percent"].items())
        modes = "; ".join(f"{m['name']} wn {m['wn_rad_s']:.3f} zeta {m['zeta']:.3f}" for m in report["modes"])
        print(
            f"{minutes:g} min flight ({samples} samples, {report['log']['records']} records, "
            f"{log.stat().st_size / 1e6:.1f} MB; flown and logged in {made:.1f} s)"
        )
        print(
            f"  fault-monitor identify, whole command: median {statistics.median(walls):.2f} s "
            f"(runs: {', '.join(f'{w:.2f}' for w in walls)})"
        )
        print(
            f"  in process: reading the log {statistics.median(reads):.3f} s, identification "
            f"{statistics.median(fits):.3f} s"
        )
        print(f"  held-out fit: {fit}; {modes}")


if __name__ == "__main__":
    main()
