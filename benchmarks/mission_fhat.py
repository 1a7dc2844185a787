"""How far a monitor's fault estimate strays in manoeuvres: max |f_hat| per mission segment, no fault flown.

Run by hand (a measurement, not a test):

    python benchmarks/mission_fhat.py --plant PLANT.toml --gains GAINS.toml \\
        [--mission docs/examples/mission-manoeuvres.toml] [--aircraft c172p] [--speedup 20] [--fault bias:2@6000]

It starts ``sim-vehicle run --aircraft A --mission M`` (the vehicle's own autopilot flies it) and
``fault-monitor run --observe`` with the plant and gains given (one trim point, or an envelope once the monitor
schedules one) on loopback, reads the monitor's recording and the vehicle's truth, and prints per segment: the
largest |f_hat|, the largest |f_hat - f| (with a fault), the bank and airspeed flown, and whether an alarm
was raised at the default threshold (1 deg), and the largest altitude and airspeed deviations from the
autopilot's references. ``--compensate``: the monitor sends the fault compensation and the vehicle adds it to
its autopilot's elevator (otherwise the monitor only observes). Why observe-only by default: the autopilot
flies, as in a real flight; the monitor only watches.
"""

from __future__ import annotations

import argparse
import json
import socket
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def fly(args: argparse.Namespace, work: Path) -> tuple[Path, Path]:
    port = _free_udp_port()
    rrd, truth = work / "run.rrd", work / "truth.jsonl"
    monitor_cmd = [
        sys.executable,
        "-m",
        "monitor",
        "run",
        "--compensate" if args.compensate else "--observe",
        "--plant",
        args.plant,
        "--gains",
        args.gains,
        "--mavlink",
        f"udpin:127.0.0.1:{port}",
        "--rrd",
        str(rrd),
        "--no-truth",
        "--no-gcs-feedback",
    ]
    vehicle_cmd = [
        sys.executable,
        "-m",
        "sim_vehicle",
        "run",
        "--aircraft",
        args.aircraft,
        "--mission",
        args.mission,
        "--mavlink",
        f"udpout:127.0.0.1:{port}",
        "--speedup",
        str(args.speedup),
        "--no-zenoh",
        "--truth-jsonl",
        str(truth),
        "--seed",
        str(args.seed),
    ]
    if args.fault:
        vehicle_cmd += ["--fault", args.fault]
    if args.compensate:
        vehicle_cmd += ["--compensation"]
    if args.turbulence:
        vehicle_cmd += ["--turbulence", args.turbulence]
    with open(work / "monitor.log", "w") as mlog:
        monitor = subprocess.Popen(monitor_cmd, stdout=mlog, stderr=subprocess.STDOUT, cwd=ROOT)
        try:
            deadline = time.monotonic() + 60
            while "ready:" not in (work / "monitor.log").read_text() and time.monotonic() < deadline:
                time.sleep(0.2)
            started = time.monotonic()
            with open(work / "vehicle.log", "w") as vlog:
                rc = subprocess.run(vehicle_cmd, stdout=vlog, stderr=subprocess.STDOUT, cwd=ROOT, timeout=3600)
            print(f"flown in {time.monotonic() - started:.0f} s (vehicle exit {rc.returncode})", file=sys.stderr)
        finally:
            monitor.send_signal(2)
            monitor.wait(60)
    return rrd, truth


def table(rrd: Path, truth_path: Path, threshold: float) -> list[dict]:
    from monitor.service.recording_reader import load_recording

    recording = load_recording(rrd)
    [series] = recording.vehicles.values()
    f_hat = {s.k: float(s.f_hat[0]) for s in series.samples}
    truth = {}
    for line in truth_path.read_text().splitlines():
        d = json.loads(line)
        truth[d["k"]] = d
    rows: dict[str, dict] = defaultdict(
        lambda: {
            "n": 0,
            "max_fhat": 0.0,
            "max_err": 0.0,
            "bank": 0.0,
            "v_min": 1e9,
            "v_max": 0.0,
            "alarm": False,
            "alt_dev": 0.0,
            "v_dev": 0.0,
        }
    )
    order: list[str] = []
    for k, d in sorted(truth.items()):
        seg = d.get("segment", "?")
        if seg not in rows:
            order.append(seg)
        r = rows[seg]
        if k not in f_hat:
            continue
        f = float(d["f"][0]) if d.get("f") else 0.0
        r["n"] += 1
        r["max_fhat"] = max(r["max_fhat"], abs(f_hat[k]))
        r["max_err"] = max(r["max_err"], abs(f_hat[k] - f))
        r["bank"] = max(r["bank"], abs(d.get("bank_deg", 0.0)), key=abs)
        r["v_min"] = min(r["v_min"], d.get("airspeed_kt", 0.0))
        r["v_max"] = max(r["v_max"], d.get("airspeed_kt", 0.0))
        r["alarm"] = r["alarm"] or abs(f_hat[k]) > threshold
        ref = d.get("reference") or {}
        if "altitude_ft" in d and ref.get("altitude_ft") is not None:
            r["alt_dev"] = max(r["alt_dev"], abs(d["altitude_ft"] - ref["altitude_ft"]))
        if "airspeed_kt" in d and ref.get("airspeed_kt") is not None:
            r["v_dev"] = max(r["v_dev"], abs(d["airspeed_kt"] - ref["airspeed_kt"]))
    return [{"segment": s, **rows[s]} for s in order]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--plant", required=True)
    p.add_argument("--gains", required=True)
    p.add_argument("--mission", default=str(ROOT / "docs" / "examples" / "mission-manoeuvres.toml"))
    p.add_argument("--aircraft", default="c172p")
    p.add_argument("--speedup", type=float, default=20.0)
    p.add_argument("--fault", default=None, help="e.g. bias:2@6000 (sample index)")
    p.add_argument("--turbulence", default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--threshold", type=float, default=1.0)
    p.add_argument(
        "--compensate",
        action="store_true",
        help="the monitor sends the fault compensation (run --compensate) and the vehicle adds it to its "
        "autopilot's elevator (sim-vehicle --compensation)",
    )
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rrd, truth = fly(args, Path(tmp))
        rows = table(rrd, truth, args.threshold)
    print(
        f"{'segment':<16} {'samples':>7} {'bank deg':>8} {'kt min-max':>11} {'max|f_hat|':>10} {'max|e_f|':>9} "
        f"{'alt dev ft':>10} {'V dev kt':>8} alarm"
    )
    for r in rows:
        print(
            f"{r['segment']:<16} {r['n']:>7} {r['bank']:>8.1f} {r['v_min']:>5.0f}-{r['v_max']:<5.0f} "
            f"{r['max_fhat']:>10.2f} {r['max_err']:>9.2f} {r['alt_dev']:>10.1f} {r['v_dev']:>8.1f} "
            f"{'ALARM' if r['alarm'] else ''}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
