"""Benchmark of ``fault-monitor analyse`` on a long telemetry log (run by hand; prints figures).

Writes a 1-hour, 50 Hz flight log the way MAVProxy does (8-byte big-endian time + one frame per record:
ATTITUDE, AOA_SSA, ACTUATOR_OUTPUT_STATUS every sample, a HEARTBEAT every second), then times the whole
command (``python -m monitor analyse``, imports included) without and with ``--rrd``. Target: well under
a minute.

    /work/venv/bin/python benchmarks/bench_analyse.py [--minutes 60]
"""

from __future__ import annotations

import argparse
import os
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.bench_monitor import H, bench_plant  # noqa: E402


def write_log(path: Path, minutes: float) -> int:
    from monitor.wire.mavlink import mavlink, new_codec

    codec = new_codec(1, 1)
    n = int(minutes * 60 / H)
    stamp = struct.Struct(">Q")
    t0 = 1_700_000_000_000_000
    h_us = int(H * 1e6)
    with open(path, "wb") as fh:
        for k in range(n):
            t_us = k * h_us
            u = -0.2 * (0.5 + 0.01 * (k % 7))
            msgs = [
                mavlink.MAVLink_attitude_message(t_us // 1000, 0, 0, 0, 0, 0.01, 0),
                mavlink.MAVLink_aoa_ssa_message(t_us, 0.5 + 0.01 * (k % 7), 0.0),
                mavlink.MAVLink_actuator_output_status_message(t_us, 1, [u] + [0.0] * 31),
            ]
            if k % 50 == 0:
                msgs.append(mavlink.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3))
            for i, msg in enumerate(msgs):
                codec.send(msg)
                fh.write(stamp.pack(t0 + t_us + i * 100) + codec.file.take())
    return n


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, default=60.0)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-analyse-"))
    plant, gains = bench_plant(work)
    log = work / "flight.tlog"
    t = time.perf_counter()
    n = write_log(log, args.minutes)
    print(
        f"wrote {n} samples ({args.minutes:g} min at 50 Hz, {log.stat().st_size / 1e6:.1f} MB) in "
        f"{time.perf_counter() - t:.1f} s"
    )
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    for extra in ([], ["--rrd", str(work / "flight.rrd")]):
        t = time.perf_counter()
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "monitor",
                "analyse",
                str(log),
                "--plant",
                str(plant),
                "--gains",
                str(gains),
                *extra,
            ],
            capture_output=True,
            text=True,
            env=env,
            cwd=REPO,
        )
        elapsed = time.perf_counter() - t
        last = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else out.stderr[-300:]
        print(
            f"analyse {' '.join(extra) or '(no recording)':40s}: {elapsed:5.1f} s wall, exit {out.returncode}; {last}"
        )


if __name__ == "__main__":
    main()
