"""A scheduled envelope against one trim on a real flight model: max |f_hat| per mission segment, no fault flown.

Run by hand (a measurement, not a test; about a minute on 2 cores):

    python benchmarks/mission_envelope.py [--id-mission docs/examples/mission-identification.toml]
        [--mission docs/examples/mission-short.toml] [--schedule airspeed [--schedule bank_load_factor]]
        [--model short-period] [--known-input throttle] [--aircraft c172p] [--speedup 20] [--seed 0] [--work DIR]

1. flies the identification mission on ``sim-vehicle --aircraft NAME`` (its own autopilot), logged as a tlog;
2. identifies a plant from each of its legs (every segment with an ``excite`` key; ``fault-monitor identify
   --window`` over the leg and two seconds of its lead-in), assembles them into an envelope scheduled by the
   ``--schedule`` signals (``fault-monitor envelope``), designs it, and the first leg's plant alone;
3. flies the mission (the vehicle's autopilot, no fault), logged as a tlog;
4. analyses that log with the one-trim plant and with the envelope (``fault-monitor analyse --json``, the same
   vehicle table as ``run``) and prints per segment the largest |f_hat| of each, and the envelope's per-point
   counts.

Why tlogs and ``analyse`` rather than ``run``: the two models see the same flight, sample for sample.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from sim_vehicle.mission import load_mission  # noqa: E402 - found through the sys.path entry above
from tests.mission_logs import legs, log_mission, segments  # noqa: E402


def _monitor(*args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "monitor", *args]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}\n{done.stderr}")
    return done


def log_flight(mission: Path, work: Path, name: str, args: argparse.Namespace) -> tuple[Path, float]:
    """``mission`` flown on sim-vehicle ``--aircraft`` at ``--speedup``, every datagram into ``work/NAME.tlog``
    as a ground station logs it (``tests.mission_logs``); the log and the seconds taken."""
    start = time.monotonic()
    budget = 60.0 + 3.0 * load_mission(mission).duration / args.speedup
    tlog = log_mission(
        work,
        mission,
        "--seed",
        str(args.seed),
        aircraft=args.aircraft,
        name=name,
        budget_s=budget,
        speedup=f"{args.speedup:g}",
    )
    return tlog, time.monotonic() - start


def max_fhat(records: list[dict], start: float, end: float) -> float:
    vals = [abs(f) for r in records if start <= r["t"] < end for f in r["f_hat"]]
    return max(vals) if vals else float("nan")


def analyse(tlog: Path, plant: Path, gains: Path, rrd: Path) -> tuple[dict, list[dict]]:
    """``fault-monitor analyse --json`` with a recording, and the recording's rows (t from the first sample)."""
    report = json.loads(
        _monitor("analyse", str(tlog), "--plant", str(plant), "--gains", str(gains), "--json", "--rrd", str(rrd)).stdout
    )
    from monitor.service.recording_reader import load_recording

    rec = load_recording(rrd)
    samples = rec.vehicles[min(rec.vehicles)].samples
    t0 = samples[0].t
    rows = [{"t": s.t - t0, "f_hat": s.f_hat, "point": s.point, "inside": s.inside} for s in samples]
    return report, rows


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mission", default=str(ROOT / "docs/examples/mission-short.toml"))
    p.add_argument(
        "--id-mission",
        default=str(ROOT / "docs/examples/mission-identification.toml"),
        help="the identification mission: each segment with an excite key is a leg, identified into one point",
    )
    p.add_argument(
        "--schedule", action="append", help="the envelope's schedule signal(s) (default: airspeed); give twice for two"
    )
    p.add_argument("--model", default="short-period", help="identify's --model for every leg (default: short-period)")
    p.add_argument(
        "--known-input", action="append", default=[], help="identify's --known-input for every leg (e.g. throttle)"
    )
    p.add_argument("--aircraft", default="c172p", help="the JSBSim aircraft both missions are flown on")
    p.add_argument("--speedup", type=float, default=20.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--work", help="keep the files here (default: a temporary directory)")
    args = p.parse_args()
    schedule = args.schedule or ["airspeed"]
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="mission-envelope-"))
    work.mkdir(parents=True, exist_ok=True)
    mission, id_mission = Path(args.mission), Path(args.id_mission)

    # 1-2. identification legs, plants, the envelope and the designs
    id_log, took = log_flight(id_mission, work, "identification", args)
    print(f"identification flight: {took:.1f} s", file=sys.stderr)
    plants: list[Path] = []
    for leg, a, b in legs(id_mission):
        plants.append(work / f"{args.aircraft}-{leg}.toml")
        window = f"{a - 2:g}:{b:g}"
        known = [a for name in args.known_input for a in ("--known-input", name)]
        _monitor("identify", str(id_log), "--model", args.model, *known, "--out", str(plants[-1]), "--window", window)
    env, env_gains = work / f"{args.aircraft}-env.toml", work / f"{args.aircraft}-env-gains.toml"
    one_gains = work / f"{args.aircraft}-one-gains.toml"
    _monitor("envelope", *map(str, plants), *(a for s in schedule for a in ("--schedule", s)), "--out", str(env))
    start = time.monotonic()
    _monitor("design", "--plant", str(env), "--out", str(env_gains), "--jobs", "2", "--quiet")
    print(f"envelope design: {time.monotonic() - start:.1f} s", file=sys.stderr)
    one = plants[0]  # the first leg alone: the one-trim model
    _monitor("design", "--plant", str(one), "--out", str(one_gains), "--quiet")

    # 3-4. the mission, and both models over its log
    flight, took = log_flight(mission, work, "mission", args)
    print(f"mission flight: {took:.1f} s", file=sys.stderr)
    _one_report, one_rows = analyse(flight, one, one_gains, work / "one.rrd")
    env_report, scheduled = analyse(flight, env, env_gains, work / "env.rrd")
    print(f"files in {work}")
    print(f"{'segment':<14}{'one trim (' + one.stem + ')':>28}{'envelope':>12}")
    for name, a, b in segments(mission):
        print(f"{name:<14}{max_fhat(one_rows, a, b):>28.3f}{max_fhat(scheduled, a, b):>12.3f}")
    print(f"{'whole flight':<14}{max_fhat(one_rows, 0, 1e9):>28.3f}{max_fhat(scheduled, 0, 1e9):>12.3f}   (deg)")
    e = env_report["envelope"]
    print(f"envelope {e['name']}: {e['samples']} samples, {e['outside']} outside the identified range")
    for point in e["points"]:
        print(f"  point {point['name']} at {point['at']}: {point['samples']} samples, {point['outside']} outside")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
