"""A monitor group at 50 Hz through a kill and a hang (run by hand; prints figures, asserts nothing).

Three ``fault-monitor run --group bench`` members, each on its own UDP port, all clients of one Zenoh router (a
session in this process). The load generator, also this process, plays ``--vehicles`` vehicles at 50 Hz, one
message per datagram, and sends every datagram to every member (a router's fan-out: MAVProxy with one output per
member); each vehicle's socket reads the commands back, the source port telling which member answered. After
``--warmup`` s the owner of vehicle 1 is killed (SIGKILL); ``--gap`` s later the owner of the first vehicle owned by
another survivor is stopped (SIGSTOP) for ``--stop`` s and resumed (SIGCONT); 1 s after that the killed member is
started again under its name (a member that joins a group in flight: it copies the owners' states, then takes its
vehicles back).

Printed per event: the vehicles it concerned, the time from the signal to each one's first answer in time from its
new owner (the takeover; the first sample after it is answered within one period), the samples not answered within
one sample period around it, and after the SIGCONT how long the resumed member took to answer its vehicles again and
whether any of their samples went unanswered meanwhile, and the same for the member that joined. Overall: the
fraction answered in time, the samples answered by two members, and how many of those got two different commands
(the command frames compared byte for byte).

    python benchmarks/bench_group.py [--vehicles 10] [--warmup 3] [--gap 3] [--stop 1] [--tail 5]
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from benchmarks.bench_monitor import _CMD_ID, _CMD_TIME, H, _free_udp_port, bench_plant, sample_frames  # noqa: E402
from monitor.process import stop_process_group  # noqa: E402
from monitor.service.group import owner  # noqa: E402
from tests.monitor_bus import zenoh_bus  # noqa: E402

MEMBERS = ("m1", "m2", "m3")


def start_member(name: str, port: int, plant: Path, gains: Path, endpoint: str, log: Path) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "monitor", "--log-level", "INFO", "run", "--plant", str(plant), "--gains", str(gains)]
    cmd += ["--mavlink", f"udpin:127.0.0.1:{port}", "--vehicle-timeout", "60", "--no-truth", "--group", "bench"]
    cmd += ["--name", name, "--zenoh-mode", "client", "--zenoh-connect", endpoint]
    return subprocess.Popen(
        cmd,
        stdout=open(log, "wb"),
        stderr=subprocess.STDOUT,
        cwd=REPO,
        start_new_session=True,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )


class Fleet:
    """The vehicles: one socket each, every sample to every member; what came back, per (vehicle, k)."""

    def __init__(self, vehicles: int, n: int, ports: dict[str, int]) -> None:
        self.frames = [sample_frames(v + 1, n) for v in range(vehicles)]
        self.targets = [("127.0.0.1", p) for p in ports.values()]
        self.member_of_port = {p: m for m, p in ports.items()}
        self.socks = []
        for _ in range(vehicles):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            s.setblocking(False)
            self.socks.append(s)
        self.by_fd = {s.fileno(): v for v, s in enumerate(self.socks)}
        self.poller = select.poll()
        for fd in self.by_fd:
            self.poller.register(fd, select.POLLIN)
        self.sent_at: dict[tuple[int, int], float] = {}
        # (vehicle, k) -> [(member, arrival time, command payload)]
        self.answers: dict[tuple[int, int], list[tuple[str, float, bytes]]] = {}

    def send(self, k: int) -> None:
        for v, sock in enumerate(self.socks):
            for frame in self.frames[v][k]:
                for target in self.targets:
                    sock.sendto(frame, target)
            self.sent_at[(v, k)] = time.perf_counter()

    def receive(self, timeout_ms: int) -> None:
        h_us = int(H * 1e6)
        for fd, _ in self.poller.poll(timeout_ms):
            v = self.by_fd[fd]
            while True:
                try:
                    data, addr = self.socks[v].recvfrom(4096)
                except BlockingIOError:
                    break
                now = time.perf_counter()
                i = 0
                while i + 12 <= len(data):
                    mlen = data[i + 1]
                    msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
                    if msgid == _CMD_ID:
                        k = _CMD_TIME.unpack_from(data, i + 10)[0] // h_us
                        member = self.member_of_port.get(addr[1], "?")
                        self.answers.setdefault((v, k), []).append((member, now, bytes(data[i + 10 : i + 10 + mlen])))
                    i += 12 + mlen + (13 if data[i + 2] & 1 else 0)

    def timely(self, v: int, k: int) -> tuple[str, float] | None:
        """The first answer of (v, k) if it came within one sample period of the sample: (member, arrival)."""
        sent = self.sent_at.get((v, k))
        for member, at, _ in sorted(self.answers.get((v, k), []), key=lambda a: a[1]):
            if sent is not None and at - sent <= H:
                return member, at
        return None


def event_report(fleet: Fleet, n: int, vehicles: list[int], at: float, before: str, label: str) -> None:
    """Takeover time and missed samples of ``vehicles`` (owned by ``before`` until ``at``)."""
    for v in vehicles:
        after = [k for k in range(n) if fleet.sent_at.get((v, k), 0.0) >= at]
        missed = [k for k in after[: int(2.0 / H)] if fleet.timely(v, k) is None]
        first = next(((k, t) for k in after if (t := fleet.timely(v, k)) is not None and t[0] != before), None)
        took = (
            f"{(first[1][1] - at) * 1e3:.0f} ms (by {first[1][0]}, sample {first[0] - after[0]} after)"
            if first
            else "never"
        )
        print(f"  {label}: vehicle {v + 1}: new owner's first answer in time {took}; missed in 2 s: {len(missed)}")


def back_report(fleet: Fleet, n: int, vehicles: list[int], member: str, k0: int, at: float, label: str, span: float):
    """When ``member`` answered ``vehicles`` again after ``at`` (sample ``k0``), and what was missed meanwhile."""
    for v in vehicles:
        back = next((k for k in range(k0, n) if (t := fleet.timely(v, k)) is not None and t[0] == member), None)
        missed = [k for k in range(k0, min(n, k0 + int(span / H))) if fleet.timely(v, k) is None]
        when = f"{(fleet.sent_at[(v, back)] - at) * 1e3:.0f} ms after" if back is not None else "never"
        near = [k - back for k in missed] if back is not None else missed
        print(f"  {label}: vehicle {v + 1}: answered by {member} again from {when}; missed: {len(missed)} {near}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vehicles", type=int, default=10)
    parser.add_argument("--warmup", type=float, default=3.0, help="seconds before the kill (default: 3)")
    parser.add_argument("--gap", type=float, default=3.0, help="seconds from the kill to the stop (default: 3)")
    parser.add_argument("--stop", type=float, default=1.0, help="seconds stopped (default: 1)")
    parser.add_argument("--tail", type=float, default=5.0, help="seconds flown after the SIGCONT (default: 5)")
    args = parser.parse_args()
    workdir = Path(tempfile.mkdtemp(prefix="bench-group-"))
    plant, gains = bench_plant(workdir)
    ports = {m: _free_udp_port() for m in MEMBERS}
    n = int((args.warmup + args.gap + args.stop + args.tail) / H)
    k_kill, k_stop = int(args.warmup / H), int((args.warmup + args.gap) / H)
    k_cont = k_stop + int(args.stop / H)
    k_join = k_cont + int(1.0 / H)
    sysids = range(1, args.vehicles + 1)
    killed = owner("uav", 1, MEMBERS)
    survivors = [m for m in MEMBERS if m != killed]
    stopped = next(o for s in sysids if (o := owner("uav", s, survivors)) != owner("uav", 1, survivors))
    of_killed = [s - 1 for s in sysids if owner("uav", s, MEMBERS) == killed]
    of_stopped = [s - 1 for s in sysids if owner("uav", s, survivors) == stopped]
    with zenoh_bus() as bus:
        procs = {m: start_member(m, ports[m], plant, gains, bus.endpoint, workdir / f"{m}.log") for m in MEMBERS}
        try:
            deadline = time.monotonic() + 60
            while not all("in step" in (workdir / f"{m}.log").read_text(errors="replace") for m in MEMBERS):
                if time.monotonic() > deadline:
                    raise SystemExit("the members did not get in step; logs in " + str(workdir))
                time.sleep(0.1)
            fleet = Fleet(args.vehicles, n, ports)
            start = time.perf_counter() + 0.1
            marks: dict[str, float] = {}
            for k in range(n):
                due = start + k * H
                while (wait := due - time.perf_counter()) > 0:
                    fleet.receive(max(0, int(wait * 1000)))
                if k == k_kill:
                    procs[killed].kill()
                    marks["kill"] = time.perf_counter()
                elif k == k_stop:
                    os.kill(procs[stopped].pid, signal.SIGSTOP)
                    marks["stop"] = time.perf_counter()
                elif k == k_cont:
                    os.kill(procs[stopped].pid, signal.SIGCONT)
                    marks["cont"] = time.perf_counter()
                elif k == k_join:
                    procs[f"{killed} again"] = start_member(
                        killed, ports[killed], plant, gains, bus.endpoint, workdir / f"{killed}-again.log"
                    )
                    marks["join"] = time.perf_counter()
                fleet.send(k)
                fleet.receive(0)
            end = time.perf_counter() + 0.5
            while time.perf_counter() < end:
                fleet.receive(50)
        finally:
            if procs[stopped].poll() is None:
                os.kill(procs[stopped].pid, signal.SIGCONT)
            for proc in procs.values():
                stop_process_group(proc)
    total = args.vehicles * n
    timely = sum(fleet.timely(v, k) is not None for v in range(args.vehicles) for k in range(n))
    twice = [key for key, a in fleet.answers.items() if len({m for m, _, _ in a}) > 1]
    different = [key for key in twice if len({p for _, _, p in fleet.answers[key]}) > 1]
    print(f"{args.vehicles} vehicles x {1 / H:.0f} Hz, 3 members; logs in {workdir}")
    print(f"kill {killed} (owned {[v + 1 for v in of_killed]}) at {args.warmup:g} s:")
    event_report(fleet, n, of_killed, marks["kill"], killed, "SIGKILL")
    print(f"stop {stopped} (owned {[v + 1 for v in of_stopped]}) at {args.warmup + args.gap:g} s for {args.stop:g} s:")
    event_report(fleet, n, of_stopped, marks["stop"], stopped, "SIGSTOP")
    back_report(fleet, n, of_stopped, stopped, k_cont, marks["cont"], "SIGCONT", 1.0)
    print(f"start {killed} again at {args.warmup + args.gap + args.stop + 1:g} s (a member that joins):")
    back_report(fleet, n, of_killed, killed, k_join, marks["join"], "joined", args.tail - 1.0)
    others = [v for v in range(args.vehicles) if v not in of_killed and v not in of_stopped]
    missed_others = sum(fleet.timely(v, k) is None for v in others for k in range(n))
    print(
        f"answered within one period: {timely}/{total} ({100 * timely / total:.2f} %); vehicles no event concerned: "
        f"{missed_others} missed; answered by two members: {len(twice)}, with different commands: {len(different)}"
    )


if __name__ == "__main__":
    main()
