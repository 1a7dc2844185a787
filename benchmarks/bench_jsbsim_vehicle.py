"""Benchmark of ``sim-vehicle run --aircraft``: how fast a JSBSim flight runs at full speed (run by hand).

Two figures for a 10-minute flight of c172p sampled at 20 Hz (12,000 samples, 72,000 JSBSim steps):

* in process: load + trim + the event simulation with a sink that drops everything (the flight model's and
  the event logic's own cost), without and with light turbulence;
* the daemon as a user runs it: ``python -m sim_vehicle run --aircraft c172p --steps 12000 --speedup 1e5``
  (imports, trim, MAVLink encoding, the truth stream to a JSON-lines file, the UDP sends) with a plain UDP
  listener counting the samples it receives. Target: well under a minute.

    /work/venv/bin/python benchmarks/bench_jsbsim_vehicle.py [--minutes 10] [--rate 20]
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


class _Drop:
    def send_sample(self, sample) -> None:
        pass

    def send_heartbeat(self) -> None:
        pass

    def publish_truth(self, payload) -> None:
        pass


def in_process(steps: int, rate: float, turbulence: str) -> tuple[float, float]:
    """(seconds to load and trim, seconds to fly ``steps`` samples)."""
    from monitor.wire.specs import parse_delay_spec
    from sim_vehicle.jsbsim_model import AircraftSpec, JSBSimFlightModel
    from sim_vehicle.simulation import Simulation

    t0 = time.perf_counter()
    model = JSBSimFlightModel(AircraftSpec("c172p", h=1.0 / rate, turbulence=turbulence, seed=1))
    t1 = time.perf_counter()
    sim = Simulation(None, _Drop(), steps=steps, model=model, delay=parse_delay_spec(f"uniform:0:{0.46 / rate:g}"))
    while not sim.done:
        sim.run_until(sim.next_time())
    return t1 - t0, time.perf_counter() - t1


def daemon(steps: int, rate: float, work: Path) -> tuple[float, int]:
    """(wall seconds of the whole command, samples a UDP listener received)."""
    from monitor.wire.mavlink import new_codec

    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(0.2)
    port = rx.getsockname()[1]
    got: set[int] = set()
    stop = threading.Event()

    def listen() -> None:
        codec = new_codec(255, 190)
        while not stop.is_set():
            try:
                data = rx.recv(65535)
            except TimeoutError:
                continue
            for msg in codec.parse_buffer(data) or []:
                if msg.get_type() == "AOA_SSA":
                    got.add(msg.time_usec)

    thread = threading.Thread(target=listen, daemon=True)
    thread.start()
    cmd = [
        sys.executable,
        "-m",
        "sim_vehicle",
        "run",
        "--aircraft",
        "c172p",
        "--rate",
        f"{rate:g}",
        "--steps",
        str(steps),
        "--speedup",
        "1e5",
        "--no-zenoh",
        "--mavlink",
        f"udpout:127.0.0.1:{port}",
        "--truth-jsonl",
        str(work / "truth.jsonl"),
        "--turbulence",
        "light",
        "--log-level",
        "WARNING",
    ]
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, env={**os.environ, "RERUN_ANALYTICS": "0"})
    wall = time.perf_counter() - t
    time.sleep(0.5)
    stop.set()
    thread.join(2)
    rx.close()
    if proc.returncode != 0:
        raise SystemExit(f"sim-vehicle failed ({proc.returncode}): {proc.stderr[-2000:]}")
    return wall, len(got)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--rate", type=float, default=20.0)
    args = parser.parse_args()
    steps = int(round(args.minutes * 60 * args.rate))
    work = Path(tempfile.mkdtemp(prefix="bench-jsbsim-"))
    print(
        f"c172p, {args.minutes:g} simulated minutes at {args.rate:g} Hz: {steps} samples, "
        f"{steps * round(120 / args.rate)} JSBSim steps"
    )
    for turbulence in ("none", "light"):
        load, fly = in_process(steps, args.rate, turbulence)
        print(
            f"  in process, turbulence {turbulence:5s}: load + trim {load * 1e3:.0f} ms, flight {fly:.2f} s "
            f"({steps / fly:,.0f} samples/s, {steps * 60 / args.rate / 60 / fly:.0f}x real time)"
        )
    wall, received = daemon(steps, args.rate, work)
    print(
        f"  daemon (sim-vehicle run ... --speedup 1e5, light turbulence, truth to JSONL, UDP to a listener): "
        f"{wall:.2f} s wall incl. start-up, {received}/{steps} samples received "
        f"({args.minutes * 60 / wall:.0f}x real time; target: well under 60 s)"
    )


if __name__ == "__main__":
    main()
