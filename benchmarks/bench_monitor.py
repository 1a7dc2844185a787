"""Benchmark of the live monitor over real sockets (run by hand; prints figures, asserts nothing).

1. Round trip at 10 vehicles x 50 Hz, for both framings: *packed* (ATTITUDE + AOA_SSA +
   ACTUATOR_OUTPUT_STATUS in one datagram, as sim-vehicle sends) and *one message per datagram* (as
   MAVProxy, mavlink-router and autopilots send). The round trip runs from the moment the sample's last
   datagram is sent to the moment its SET_ACTUATOR_CONTROL_TARGET comes back. The floor is a bare
   pymavlink echo in its own process (recvfrom, ``parse_buffer``, on AOA_SSA encode and send the reply
   with pymavlink). Target: monitor p50 <= 1.5x echo p50 on one-message-per-datagram traffic.
2. Answered fraction at 100 vehicles x 50 Hz, both framings. Target: >= 99 %.
3. Under a flood (``--flood``): 10 vehicles x 50 Hz one message per datagram while another process
   sends 2,000 junk datagrams/s, each from a fresh source port (thousands of peers). Target: every sample
   of the real vehicles answered.
4. In-process cost per sample of ``Pipeline.on_frames`` (parse + assemble + estimator + command + FHAT
   feedback + Zenoh hand-off), both framings.

The plant is paper-continuous re-sampled at h = 20 ms (50 Hz), with placeholder gains (the figures do not
depend on them). Load generator: this process, one UDP socket per vehicle.

    /work/venv/bin/python benchmarks/bench_monitor.py [--seconds 10] [--skip-inprocess]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import select
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

H = 0.02
_CMD_ID = 139
_CMD_TIME = struct.Struct("<Q")

ECHO_SERVER = r"""
import os, socket, sys
os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as m
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("127.0.0.1", int(sys.argv[1])))
sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
codecs = {}
class Sink:
    def write(self, data): pass
while True:
    data, addr = sock.recvfrom(65535)
    codec = codecs.get(addr)
    if codec is None:
        codec = codecs[addr] = m.MAVLink(Sink(), srcSystem=255, srcComponent=191)
        codec.robust_parsing = True
    for msg in codec.parse_buffer(data) or []:
        if msg.get_type() == "AOA_SSA":
            reply = m.MAVLink_set_actuator_control_target_message(msg.time_usec, 0, msg.get_srcSystem(), 1,
                                                                  [0.0, msg.AOA / 30.0] + [0.0] * 6)
            sock.sendto(reply.pack(codec), addr)
"""


def bench_plant(directory: Path) -> tuple[Path, Path]:
    """paper-continuous at 50 Hz and deadbeat observer gains for it (files in ``directory``)."""
    import numpy as np

    from monitor.design.result import DesignResult
    from monitor.gains import write_gains
    from monitor.model.closed_loop import Gains
    from monitor.model.plant import load_plant, parse_plant

    text = (REPO / "monitor/presets/paper-continuous.toml").read_text()
    text = text.replace("h = 1.0", f"h = {H}").replace("tau_max = 0.4612", f"tau_max = {0.4612 * H}")
    text = text.replace('name = "paper-continuous"', 'name = "paper-continuous-50hz"')
    plant_path = directory / "plant-50hz.toml"
    plant_path.write_text(text)
    p = parse_plant(text, str(plant_path))
    # the load generator's y answers no command, so an observer would chase a phantom fault: L = M = 0 keeps
    # the state bounded; the cost per sample does not depend on the values
    gains = Gains(
        L=np.zeros((2, 1)), M=np.zeros((1, 1)), K1=np.array([[-0.2]]), K2=np.zeros((1, 1)), K3=np.zeros((1, 1))
    )
    gains_path = directory / "gains-50hz.toml"
    write_gains(
        gains_path,
        DesignResult("bench", gains, gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0),
        p,
    )
    assert load_plant(plant_path).h == H
    return plant_path, gains_path


def sample_frames(sysid: int, n: int) -> list[list[bytes]]:
    """Per sample: the three frames, encoded by pymavlink."""
    from monitor.wire.mavlink import mavlink, new_codec

    codec = new_codec(sysid, 1)
    out = []
    for k in range(n):
        t_us = k * int(H * 1e6)
        frames = []
        for msg in (
            mavlink.MAVLink_attitude_message(t_us // 1000, 0, 0, 0, 0, 0.01, 0),
            mavlink.MAVLink_aoa_ssa_message(t_us, 0.5 + 0.01 * (k % 7), 0.0),
            mavlink.MAVLink_actuator_output_status_message(t_us, 1, [0.1] + [0.0] * 31),
        ):
            codec.send(msg)
            frames.append(codec.file.take())
        out.append(frames)
    return out


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(kind: str, port: int, plant: Path, gains: Path, log_path: str) -> subprocess.Popen:
    if kind == "echo":
        cmd = [sys.executable, "-c", ECHO_SERVER, str(port)]
    else:
        cmd = [
            sys.executable,
            "-m",
            "monitor",
            "--log-level",
            "INFO",  # the exit summary (shed, processing times) is an INFO line
            "run",
            "--plant",
            str(plant),
            "--gains",
            str(gains),
            "--mavlink",
            f"udpin:127.0.0.1:{port}",
            "--vehicle-timeout",
            "60",
            "--no-truth",
        ]
    proc = subprocess.Popen(
        cmd,
        stdout=open(log_path, "wb"),
        stderr=subprocess.STDOUT,
        cwd=REPO,
        start_new_session=True,
        env={**os.environ, "RERUN_ANALYTICS": "0"},
    )
    time.sleep(2.5 if kind == "monitor" else 0.5)  # imports, Zenoh session
    return proc


def stop_server(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(5)


def drive(
    port: int, vehicles: int, seconds: float, framing: str, answered_in_time: set | None = None
) -> tuple[list[float], int, int]:
    """Paced load: every vehicle sends one sample per H; returns (round trips in s, sent, answered).
    ``answered_in_time`` collects ``(vehicle, k)`` of the samples answered within H."""
    n = int(seconds / H)
    frames = [sample_frames(v + 1, n) for v in range(vehicles)]
    socks = []
    for _ in range(vehicles):
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        s.setblocking(False)
        socks.append(s)
    by_fd = {s.fileno(): v for v, s in enumerate(socks)}
    poller = select.poll()
    for fd in by_fd:
        poller.register(fd, select.POLLIN)
    target = ("127.0.0.1", port)
    sent_at: dict[tuple[int, int], float] = {}
    rtts: list[float] = []
    h_us = int(H * 1e6)
    start = time.perf_counter() + 0.1

    def receive(timeout_ms: int) -> None:
        for fd, _ in poller.poll(timeout_ms):
            v = by_fd[fd]
            while True:
                try:
                    data = socks[v].recv(4096)
                except BlockingIOError:
                    break
                now = time.perf_counter()
                i = 0
                while i + 12 <= len(data):  # several frames may share a datagram
                    mlen = data[i + 1]
                    msgid = data[i + 7] | data[i + 8] << 8 | data[i + 9] << 16
                    if msgid == _CMD_ID:
                        k = _CMD_TIME.unpack_from(data, i + 10)[0] // h_us
                        t0 = sent_at.pop((v, k), None)
                        if t0 is not None:
                            rtts.append(now - t0)
                            if answered_in_time is not None and now - t0 <= H:
                                answered_in_time.add((v, k))
                    i += 12 + mlen + (13 if data[i + 2] & 1 else 0)

    for k in range(n):
        due = start + k * H
        while (wait := due - time.perf_counter()) > 0:
            receive(max(0, int(wait * 1000)))
        for v in range(vehicles):
            sample = frames[v][k]
            if framing == "packed":
                socks[v].sendto(b"".join(sample), target)
            else:
                for frame in sample:
                    socks[v].sendto(frame, target)
            sent_at[(v, k)] = time.perf_counter()
        receive(0)
    end = time.perf_counter() + 1.0
    while time.perf_counter() < end and sent_at:
        receive(50)
    for s in socks:
        s.close()
    return rtts, n * vehicles, len(rtts)


FLOODER = r"""
import os, socket, sys, time
port, rate, seconds = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
end, sent = time.monotonic() + seconds, 0
while time.monotonic() < end:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.sendto(os.urandom(64), ("127.0.0.1", port))  # every datagram from a new ephemeral port
    s.close()
    sent += 1
    time.sleep(max(0.0, sent / rate - (time.monotonic() - end + seconds)))
print(sent)
"""


def overload(plant: Path, gains: Path, workdir: Path, seconds: float, fleets: list[int]) -> None:
    """Past saturation, the echo and the monitor in the same run (paired): answered, answered within one sample
    period (per second and in all), round trip p50/p99 of the answers. One message per datagram, as routers send."""
    print(f"  overload, one message per datagram, {seconds:.0f} s each, echo and monitor paired on this machine:")
    for vehicles in fleets:
        for kind in ("echo", "monitor"):
            port = _free_udp_port()
            log_path = workdir / f"{kind}-{vehicles}.log"
            proc = start_server(kind, port, plant, gains, str(log_path))
            try:
                cpu0, t0 = cpu_seconds(proc.pid), time.monotonic()
                timely: set[tuple[int, int]] = set()
                rtts, sent, answered = drive(port, vehicles, seconds, "one message per datagram", timely)
                cpu_s = cpu_seconds(proc.pid) - cpu0
                cpu = cpu_s / (time.monotonic() - t0)
            finally:
                stop_server(proc)
            in_time = sum(1 for r in rtts if r <= H)
            print(
                f"  {vehicles:3d} x 50 Hz {kind:8s}: answered {answered / sent:6.1%} ({answered / seconds:6.0f}/s), "
                f"within {H * 1e3:.0f} ms {in_time / seconds:6.0f}/s ({in_time / sent:6.1%}), "
                f"round trip p50 {pct(rtts, 50) / 1e3:6.1f} ms p99 {pct(rtts, 99) / 1e3:6.1f} ms, "
                f"CPU {cpu:4.0%} of a core ({cpu_s / max(answered, 1) * 1e6:3.0f} us per answer), "
                f"longest run without a timely answer {longest_gap(timely, vehicles):3d}"
            )
        summary = [line for line in log_path.read_text().splitlines() if "stopped:" in line]
        if summary:
            print("      monitor summary:", summary[-1].split("stopped: ", 1)[1])


def longest_gap(timely: set[tuple[int, int]], vehicles: int) -> int:
    """The most consecutive samples of one vehicle not answered in time, between its first and last timely answer
    (what ``verify --max-losses N`` must cover)."""
    worst = 0
    for v in range(vehicles):
        ks = sorted(k for vv, k in timely if vv == v)
        worst = max([worst, *(b - a - 1 for a, b in zip(ks, ks[1:], strict=False))])
    return worst


def cpu_seconds(pid: int) -> float:
    """utime + stime of ``pid`` (all its threads), in seconds (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def pct(values: list[float], p: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(p / 100 * len(values)))] * 1e6 if values else float("nan")


def inprocess(plant: Path, gains: Path, n: int = 20_000) -> None:
    from monitor.link.frames import FrameParser
    from monitor.service.daemon import MonitorConfig, build_pipeline
    from monitor.service.fleet_file import Fleet, load_model
    from monitor.service.publisher import EstimatePublisher
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    class NullLink:
        def __init__(self) -> None:
            from monitor.link.frames import FrameEncoder

            self.encoder = FrameEncoder(255, 191)

        def encoder_for(self, peer):
            return self.encoder

        def send(self, data: bytes, peer) -> None:
            pass

    session = open_session(build_config())
    publisher = EstimatePublisher(session, "bench", "bench")
    try:
        for framing in ("packed", "one message per datagram"):
            data = sample_frames(1, n)
            pipeline = build_pipeline(
                MonitorConfig(fleet=Fleet(load_model(plant, gains)), connections=[]), publisher=publisher
            )
            parser = FrameParser(pipeline.frames)
            route = (NullLink(), ("127.0.0.1", 9))
            times = []
            for sample in data:
                chunks = [b"".join(sample)] if framing == "packed" else sample
                t0 = time.perf_counter_ns()
                for chunk in chunks:
                    frames = parser.feed(chunk)
                    if frames:
                        pipeline.on_frames(route, frames, t0)
                times.append(time.perf_counter_ns() - t0)
            times.sort()
            print(
                f"  in-process per sample, {framing:25s}: p50 {times[n // 2] / 1e3:6.1f} us   "
                f"p99 {times[int(n * 0.99)] / 1e3:6.1f} us   ({pipeline.table.counters.processed} processed)"
            )
    finally:
        close_quietly(session, *publisher.close())


def where_time_goes(plant: Path, gains: Path, vehicles: int = 100, rounds: int = 200, profile: bool = False) -> None:
    """Per answered sample, in process: ``vehicles`` send one sample each (one message per datagram, real loopback
    sockets) into a real ``UdpLink``, which drains them and hands them to the pipeline, as in the daemon. Each stage
    is timed by wrapping it (a few hundred ns of wrapper each); ``profile``: cProfile's top functions as well."""
    import asyncio
    import cProfile
    import logging
    import pstats

    import monitor.service.pipeline as pipeline_module
    from monitor.link.transports import UdpLink, parse_connection
    from monitor.service.daemon import MonitorConfig, build_pipeline
    from monitor.service.fleet_file import Fleet, load_model
    from monitor.service.publisher import EstimatePublisher
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    logging.disable(logging.WARNING)  # the load generator's vehicles never apply a command: one WARNING each
    spent: dict[str, int] = {}

    def timed(name: str, fn):
        def wrapper(*args, **kwargs):
            t = time.perf_counter_ns()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] = spent.get(name, 0) + time.perf_counter_ns() - t

        return wrapper

    session = open_session(build_config())
    publisher = EstimatePublisher(session, "bench", "bench")
    pipeline = build_pipeline(MonitorConfig(fleet=Fleet(load_model(plant, gains)), connections=[]), publisher=publisher)
    table = pipeline.table
    stages = {
        "estimator step and checks (VehicleTable.process)": (table, "process"),
        "decode + assemble (VehicleTable.message)": (table, "message"),
        "Zenoh: format the round's estimates (flush)": (publisher, "flush"),
    }
    for name, (owner, attr) in stages.items():
        setattr(owner, attr, timed(name, getattr(owner, attr)))
    pipeline._flush = publisher.flush
    originals = (pipeline_module.command_frame, pipeline_module.fhat_frames)
    pipeline_module.command_frame = timed("encode the command", pipeline_module.command_frame)
    pipeline_module.fhat_frames = timed("encode the FHAT feedback", pipeline_module.fhat_frames)
    frames = [sample_frames(v + 1, rounds) for v in range(vehicles)]
    senders = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(vehicles)]
    profiler = cProfile.Profile()

    async def run() -> int:
        link = UdpLink(parse_connection("udpin:127.0.0.1:0"), 0, pipeline.on_reads, pipeline.frames, None)
        await link.start()
        assert link.sock is not None and link._loop is not None
        link._loop.remove_reader(link.sock.fileno())  # driven by hand below, one round per sample instant
        link.send = timed("sendto (command + FHAT, one datagram)", link.send)  # type: ignore[method-assign]
        address = link.sock.getsockname()
        for sock in senders:
            sock.setblocking(False)
        total = 0
        for k in range(rounds):
            for v in range(vehicles):
                for frame in frames[v][k]:
                    senders[v].sendto(frame, address)
            t = time.perf_counter_ns()
            if profile:
                profiler.enable()
            for _ in range(3 * vehicles // link.burst + 1):  # the daemon's reader callbacks: drain, parse, answer
                link._readable()
            while pipeline.answer():
                pass
            if profile:
                profiler.disable()
            total += time.perf_counter_ns() - t
            for sock in senders:  # the replies, unread by anyone: out of the way
                with contextlib.suppress(BlockingIOError):
                    while sock.recv(4096):
                        pass
        link.close()
        return total

    try:
        total = asyncio.run(run())
    finally:
        pipeline_module.command_frame, pipeline_module.fhat_frames = originals
        for sock in senders:
            sock.close()
        close_quietly(session, *publisher.close())
        logging.disable(logging.NOTSET)
    n = table.counters.processed
    print(f"  where the time goes, per answered sample ({vehicles} vehicles, {n} samples, {table.counters.shed} shed):")
    print(f"    {'all of it (drain, parse, answer; wrappers included)':55s} {total / n / 1e3:6.1f} us")
    accounted = sum(spent.values())
    for name, ns in sorted(spent.items(), key=lambda item: -item[1]):
        print(f"    {name:55s} {ns / n / 1e3:6.1f} us")
    print(f"    {'the rest: recvmsg x3, frame parsing x3, routing, loop':55s} {(total - accounted) / n / 1e3:6.1f} us")
    if profile:
        stats = pstats.Stats(profiler)
        stats.sort_stats("tottime").print_stats(15)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each paced run (default: 10)")
    parser.add_argument("--skip-inprocess", action="store_true")
    parser.add_argument("--flood", action="store_true", help="only the flood run")
    parser.add_argument(
        "--profile", action="store_true", help="only: where the time goes per sample, with cProfile's top functions"
    )
    parser.add_argument(
        "--reuse",
        action="store_true",
        help="only: one monitor serves 10 vehicles, then at once 100 (ids 1-10 again, from new ports)",
    )
    parser.add_argument(
        "--overload",
        type=int,
        nargs="*",
        metavar="VEHICLES",
        help="only: echo and monitor past saturation, paired (default fleets: 100 200)",
    )
    args = parser.parse_args()
    os.environ.setdefault("RERUN_ANALYTICS", "0")
    workdir = Path(tempfile.mkdtemp(prefix="bench-monitor-"))
    plant, gains = bench_plant(workdir)
    if args.profile:
        where_time_goes(plant, gains, profile=True)
        return
    if args.overload is not None:
        where_time_goes(plant, gains)
        overload(plant, gains, workdir, args.seconds, args.overload or [100, 200])
        return
    if args.flood:
        port = _free_udp_port()
        proc = start_server("monitor", port, plant, gains, str(workdir / "monitor.log"))
        flooder = subprocess.Popen(
            [sys.executable, "-c", FLOODER, str(port), "2000", str(args.seconds + 1)], stdout=subprocess.PIPE, text=True
        )
        try:
            rtts, sent, answered = drive(port, 10, args.seconds, "one message per datagram")
        finally:
            junk = flooder.communicate(timeout=args.seconds + 30)[0].strip()
            stop_server(proc)
        print(
            f"  flood of {junk} junk datagrams from fresh ports at 2,000/s: 10 x 50 Hz answered {answered}/{sent} "
            f"({answered / sent:.2%}), round trip p50 {pct(rtts, 50):.0f} us p99 {pct(rtts, 99):.0f} us"
        )
        return
    if args.reuse:  # a load generator restarted at once: its vehicles come back from new ports, k from 0 again
        port = _free_udp_port()
        proc = start_server("monitor", port, plant, gains, str(workdir / "monitor.log"))
        try:
            for vehicles in (10, 100):
                rtts, sent, answered = drive(port, vehicles, args.seconds, "one message per datagram")
                print(
                    f"  {vehicles:3d} x 50 Hz on the same monitor: answered {answered}/{sent} ({answered / sent:.2%}), "
                    f"round trip p50 {pct(rtts, 50):.0f} us (target >= 99 %)"
                )
        finally:
            stop_server(proc)
        summary = [line for line in (workdir / "monitor.log").read_text().splitlines() if "stopped:" in line]
        print("  monitor summary:", summary[-1].split("stopped: ", 1)[1] if summary else "(none)")
        return
    if not args.skip_inprocess:
        inprocess(plant, gains)
        where_time_goes(plant, gains)
    results: dict[tuple[str, str, int], tuple[list[float], int, int]] = {}
    for vehicles in (10, 100):
        for framing in ("one message per datagram", "packed"):
            for kind in ("echo", "monitor"):
                port = _free_udp_port()
                proc = start_server(kind, port, plant, gains, str(workdir / f"{kind}.log"))
                try:
                    results[kind, framing, vehicles] = drive(port, vehicles, args.seconds, framing)
                finally:
                    stop_server(proc)
                rtts, sent, answered = results[kind, framing, vehicles]
                print(
                    f"  {vehicles:3d} x 50 Hz, {framing:25s} {kind:8s}: round trip p50 {pct(rtts, 50):7.0f} us  "
                    f"p99 {pct(rtts, 99):7.0f} us   answered {answered}/{sent} ({answered / sent:.2%})"
                )
            echo, mon = results["echo", framing, vehicles][0], results["monitor", framing, vehicles][0]
            print(
                f"      -> monitor / echo p50 = {pct(mon, 50) / pct(echo, 50):.2f}x"
                + (
                    "   (target <= 1.5x on one message per datagram)"
                    if vehicles == 10
                    else "   (target: monitor answers >= 99 %)"
                )
            )
    summary = [line for line in (workdir / "monitor.log").read_text().splitlines() if "stopped:" in line]
    if summary:
        print("  last monitor summary:", summary[-1].split("stopped: ", 1)[1])


if __name__ == "__main__":
    main()
