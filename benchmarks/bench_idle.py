"""What an idle ``fault-monitor run`` costs: CPU with no vehicle at all (run by hand; prints figures, asserts nothing).

On a companion computer in the aircraft an idle monitor's CPU is battery. This starts, one after the other:

* a bare Zenoh peer (the session alone, configured as the monitor's: loopback, no scouting): the floor;
* ``fault-monitor run`` with no vehicle (a UDP link nobody sends to);
* the same with ``--rrd`` (the recorder's writer thread);
* the same as a lone member of a monitor group (``--group``: a beat every 0.1 s);

and for each reads the process's user + system CPU time from ``/proc/<pid>/stat`` at the start and the end
of a ``--seconds`` window (20 s) that begins once it is ready, as a percentage of one core. Target: under 1 %
for the monitor, with and without ``--rrd``. The machine may be shared: other processes do not count in a
process's own CPU time, but they stretch its wake-ups a little; the peer's figure, taken in the same run, is
the reference.

    python benchmarks/bench_idle.py [--seconds 20]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.bench_monitor import _free_udp_port, bench_plant, cpu_seconds  # noqa: E402
from monitor.process import stop_process_group  # noqa: E402

PEER = r"""
import sys, time
from monitor.wire.zenoh_session import build_config, open_session
session = open_session(build_config())
print("ready", flush=True)
time.sleep(float(sys.argv[1]))
session.close()
"""


def measure(cmd: list[str], log_path: Path, seconds: float, ready: str) -> float:
    """Percent of one core that ``cmd`` burns over ``seconds``, once its log shows ``ready``."""
    import subprocess

    with open(log_path, "wb") as log:
        proc = subprocess.Popen(
            cmd,
            stdout=log,
            stderr=subprocess.STDOUT,
            cwd=REPO,
            start_new_session=True,
            env={**os.environ, "RERUN_ANALYTICS": "0"},
        )
    try:
        deadline = time.monotonic() + 60
        while ready not in log_path.read_text(errors="replace"):
            if proc.poll() is not None or time.monotonic() > deadline:
                raise SystemExit(f"{cmd[2:5]} did not become ready:\n{log_path.read_text()[-2000:]}")
            time.sleep(0.1)
        time.sleep(2.0)  # start-up work (imports finishing, first heartbeats) is not idling
        c0, t0 = cpu_seconds(proc.pid), time.monotonic()
        time.sleep(seconds)
        c1, t1 = cpu_seconds(proc.pid), time.monotonic()
    finally:
        stop_process_group(proc)
    return 100.0 * (c1 - c0) / (t1 - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=20.0, help="measuring window per process (default: 20)")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-idle-"))
    plant, gains = bench_plant(workdir)
    monitor = [sys.executable, "-m", "monitor", "--log-level", "INFO", "run", "--plant", str(plant)]
    monitor += ["--gains", str(gains), "--no-truth"]
    runs = {
        "bare Zenoh peer": ([sys.executable, "-c", PEER, str(args.seconds + 30)], "ready"),
        "fault-monitor run, no vehicle": (monitor, "ready:"),
        "fault-monitor run --rrd, no vehicle": (monitor + ["--rrd", str(workdir / "idle.rrd")], "ready:"),
        # a group member beats every 0.1 s from its loop (its only periodic work beyond the 1 Hz housekeeping)
        "fault-monitor run --group, no vehicle": (monitor + ["--group", "idle", "--name", "m1"], "ready:"),
    }
    print(f"idle CPU over {args.seconds:.0f} s (user + system, % of one core; the machine may be shared):")
    for i, (what, (cmd, ready)) in enumerate(runs.items()):
        if cmd[0] == sys.executable and "monitor" in cmd[:3]:
            cmd = [*cmd, "--mavlink", f"udpin:127.0.0.1:{_free_udp_port()}"]
        percent = measure(cmd, workdir / f"idle-{i}.log", args.seconds, ready)
        print(f"  {what:38s} {percent:5.2f} %   (target for the monitor: < 1 %)")


if __name__ == "__main__":
    main()
