"""Benchmark of the live monitor (run by hand; prints figures, asserts nothing).

1. Per-sample processing time, p50/p99, of the monitor's handling of one telemetry datagram
   (parse + estimator step + command encode + sendto + Zenoh hand-off, exactly ``Monitor.on_datagram``
   with a real Zenoh session and publisher thread), and in the same run of a bare pymavlink echo of the
   same datagrams (parse + encode the reply + sendto): the floor. Target: monitor <= 1.5x echo.
2. Vehicle-samples per second one ``fault-monitor run`` process sustains with 1, 10, 100 vehicles: a
   load generator (this process, one UDP socket per vehicle, datagrams pre-encoded) keeps a window of
   samples in flight and counts the commands that come back. Target: >= 10,000 vehicle-samples/s.

    /work/venv/bin/python benchmarks/bench_monitor.py [--samples 20000] [--vehicles 1,10,100] [--gains G]
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


def percentiles(ns: list[int]) -> tuple[float, float]:
    ns = sorted(ns)
    return ns[len(ns) // 2] / 1e3, ns[int(len(ns) * 0.99)] / 1e3


def make_gains(path: str | None) -> str:
    if path:
        return path
    from monitor.design.certified import design_certified
    from monitor.gains import write_gains
    from monitor.plant import load_plant

    out = os.path.join(tempfile.mkdtemp(prefix="bench-monitor-"), "gains.toml")
    plant = load_plant("paper-continuous")
    write_gains(out, design_certified(plant), plant)
    return out


def datagrams(sysid: int, n: int) -> list[bytes]:
    from monitor.wire.mavlink import VEHICLE_COMPONENT, Sample, encode_sample, new_codec

    codec = new_codec(sysid, VEHICLE_COMPONENT)
    return [encode_sample(codec, Sample(sysid, k, float(k), 0.5 + 0.01 * (k % 7), 0.2, 0.1), 1.0) for k in range(n)]


def per_sample(gains: str, n: int) -> None:
    from monitor.service.daemon import Monitor, MonitorConfig
    from monitor.service.publisher import EstimatePublisher
    from monitor.service.vehicles import Fleet, load_model
    from monitor.wire.mavlink import MONITOR_COMPONENT, Command, encode_command, new_codec, sample_index
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    data = datagrams(1, n)
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    target = sink.getsockname()
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    out.setblocking(False)

    def send(frame: bytes, addr) -> None:
        try:
            out.sendto(frame, target)
        except BlockingIOError:
            pass

    def drain() -> None:
        sink.setblocking(False)
        try:
            while True:
                sink.recv(4096)
        except BlockingIOError:
            pass

    def echo_run() -> list[int]:
        codec = new_codec(255, MONITOR_COMPONENT)
        times = []
        for i, d in enumerate(data):
            t0 = time.perf_counter_ns()
            for msg in codec.parse_buffer(d) or []:
                if msg.get_type() == "AOA_SSA":
                    send(encode_command(codec, Command(1, sample_index(msg.time_usec, 1.0), msg.AOA), 1.0), None)
            times.append(time.perf_counter_ns() - t0)
            if i % 100 == 0:
                drain()
        return times

    session = open_session(build_config())
    publisher = EstimatePublisher(session, "bench", "bench")
    try:
        def monitor_run() -> list[int]:
            monitor = Monitor(MonitorConfig(fleet=Fleet(load_model("paper-continuous", gains))), send=send,
                              publisher=publisher)
            times = []
            for i, d in enumerate(data):
                t0 = time.perf_counter_ns()
                monitor.on_datagram(d, ("127.0.0.1", 9), t0)
                times.append(time.perf_counter_ns() - t0)
                if i % 100 == 0:
                    drain()
            return times

        echo_run(), monitor_run()  # warm up
        e1, m1, e2, m2 = echo_run(), monitor_run(), echo_run(), monitor_run()
        (e50, e99), (m50, m99) = percentiles(e1 + e2), percentiles(m1 + m2)
        print(f"per sample ({2 * n} datagrams each, interleaved runs)")
        print(f"  bare pymavlink echo : p50 {e50:6.1f} us   p99 {e99:6.1f} us")
        print(f"  monitor             : p50 {m50:6.1f} us   p99 {m99:6.1f} us   ratio p50 {m50 / e50:.2f}x "
              f"(target <= 1.5x)   Zenoh drops {publisher.dropped}")
    finally:
        close_quietly(session, *publisher.close())


def throughput(gains: str, vehicles: int, per_vehicle: int, window: int = 64) -> tuple[float, int, int]:
    """Start a real monitor daemon, drive ``vehicles`` sysids, return (vehicle-samples/s, sent, answered)."""
    from tests.daemons import free_udp_port

    port = free_udp_port()
    log = tempfile.NamedTemporaryFile(prefix="bench-monitor-", suffix=".log", delete=False)
    proc = subprocess.Popen([sys.executable, "-m", "monitor", "--log-level", "WARNING", "run", "--plant",
                             "paper-continuous", "--gains", gains, "--mavlink", f"udpin:127.0.0.1:{port}",
                             "--vehicle-timeout", "60"], stdout=log, stderr=subprocess.STDOUT, cwd=REPO,
                            start_new_session=True)
    socks = []
    try:
        time.sleep(2.0)  # start-up (imports, Zenoh session)
        payload = [datagrams(v + 1, per_vehicle) for v in range(vehicles)]
        for _ in range(vehicles):
            s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
            s.setblocking(False)
            socks.append(s)
        target = ("127.0.0.1", port)
        sent = answered = 0
        fds = {s.fileno(): s for s in socks}
        poller = select.poll()
        for fd in fds:
            poller.register(fd, select.POLLIN)
        t0 = time.perf_counter()
        order = [(v, k) for k in range(per_vehicle) for v in range(vehicles)]
        idle_since = None
        while answered < len(order):
            while sent < len(order) and sent - answered < window:
                v, k = order[sent]
                socks[v].sendto(payload[v][k], target)
                sent += 1
            events = poller.poll(200)
            if not events:
                if sent == len(order):
                    idle_since = idle_since or time.perf_counter()
                    if time.perf_counter() - idle_since > 1.0:
                        break  # some replies will never come (socket buffers overflowed)
                else:
                    answered = sent  # lost on the way: refill the window rather than stall
                continue
            idle_since = None
            for fd, _ in events:
                try:
                    while True:
                        fds[fd].recv(4096)
                        answered += 1
                except BlockingIOError:
                    pass
        elapsed = time.perf_counter() - t0
        return answered / elapsed, sent, answered
    finally:
        for s in socks:
            s.close()
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
        log.close()
        summary = [line for line in Path(log.name).read_text().splitlines() if "stopped:" in line]
        if summary:
            print("    monitor:", summary[-1].split("stopped: ", 1)[1])
        os.unlink(log.name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=20_000)
    parser.add_argument("--vehicles", default="1,10,100")
    parser.add_argument("--total", type=int, default=30_000, help="vehicle-samples per throughput run")
    parser.add_argument("--gains", help="gains file for paper-continuous (default: design one, ~5 s)")
    args = parser.parse_args()
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    gains = make_gains(args.gains)
    per_sample(gains, args.samples)
    print("throughput of one `fault-monitor run` process (load generator in another process)")
    for v in (int(x) for x in args.vehicles.split(",")):
        rate, sent, answered = throughput(gains, v, max(1, args.total // v))
        print(f"  {v:4d} vehicles: {rate:9.0f} vehicle-samples/s ({answered}/{sent} answered; target >= 10,000)")


if __name__ == "__main__":
    main()
