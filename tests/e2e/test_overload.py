"""Current, not queued: a monitor that cannot keep up answers each vehicle's newest sample and sheds the older ones.

Why SIGSTOP: it makes the overload exact and independent of the machine's speed. While the monitor is stopped
the vehicle's samples queue in its socket, as they do behind a monitor too slow for its fleet; when it resumes
it finds them all at once. Then only the newest may be answered (the others' commands would be late), the rest
are shed: counted per vehicle in the summary and the recording, lost samples to the estimator (it predicts
across them: ``skipped``), and one WARNING per overload episode.
"""

from __future__ import annotations

import os
import re
import select
import signal
import socket
import threading
import time
from pathlib import Path

from monitor.service.recording_reader import load_recording
from monitor.wire.mavlink import mavlink, new_codec
from tests.daemons import Daemon, free_tcp_port, free_udp_port, wait_for
from tests.gains_files import hand_made_gains_file, paper_plant_sampled_at
from tests.monitor_bus import wait_ready

SYSID = 7
H_US = 1_000_000  # paper-continuous: h = 1 s, so a stopped monitor finds its queued samples well within a period


class Vehicle:
    """One vehicle on a UDP socket: one message per datagram, as routers send; reads the commands back."""

    def __init__(self, port: int, h_us: int = H_US) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.target = ("127.0.0.1", port)
        self.codec = new_codec(SYSID, 1)
        self.reader = new_codec(255, 1)
        self.h_us = h_us
        self.commands: list[int] = []  # the time_usec // h of every command received, in order
        self.sent_at: dict[int, float] = {}  # k -> monotonic time its first datagram went out
        self.round_trips: dict[int, float] = {}  # k -> seconds from its send to its command's arrival

    def send(self, k: int) -> None:
        t_us = k * self.h_us
        self.sent_at[k] = time.monotonic()  # before the send: the answer may come before the next line
        for msg in (
            mavlink.MAVLink_attitude_message(t_us // 1000, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0),
            mavlink.MAVLink_aoa_ssa_message(t_us, 0.5, 0.0),
            mavlink.MAVLink_actuator_output_status_message(t_us, 1, [0.1] + [0.0] * 31),
        ):
            self.codec.send(msg)
            self.sock.sendto(self.codec.file.take(), self.target)

    def read(self, seconds: float) -> None:
        """Collect what comes back for ``seconds`` (HEARTBEAT and FHAT ignored)."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            if not select.select([self.sock], [], [], left)[0]:
                break
            data, now = self.sock.recv(65535), time.monotonic()
            for msg in self.reader.parse_buffer(data) or []:
                if msg.get_type() == "SET_ACTUATOR_CONTROL_TARGET":
                    k = msg.time_usec // self.h_us
                    self.commands.append(k)
                    self.round_trips[k] = now - self.sent_at[k]

    def answered(self, k: int, timeout: float = 10.0) -> list[int]:
        """Wait (bounded) for the command answering k, then a little more; returns the commands of this phase."""
        start = len(self.commands)
        deadline = time.monotonic() + timeout
        while k not in self.commands[start:] and time.monotonic() < deadline:
            self.read(0.1)
        self.read(0.3)  # anything else the monitor would still send for this phase
        return self.commands[start:]


def _stopped(pid: int) -> bool:
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "T"


def _flood(monitor: Daemon, vehicle: Vehicle, ks: range, hold: float = 0.0) -> list[int]:
    """Samples ``ks`` sent while the monitor is stopped (``hold`` s more after them); returns the commands that come
    back after it resumes."""
    assert monitor.proc is not None
    os.kill(monitor.proc.pid, signal.SIGSTOP)
    try:
        wait_for(lambda: _stopped(monitor.proc.pid), 5, interval=0.005, what="the monitor stopped")
        for k in ks:
            vehicle.send(k)
        time.sleep(hold)
    finally:
        os.kill(monitor.proc.pid, signal.SIGCONT)
    return vehicle.answered(ks[-1], timeout=1.0 if hold else 10.0)


def test_a_flood_of_queued_samples_is_answered_by_the_newest_and_the_rest_shed(tmp_path: Path, gains_path) -> None:
    port = free_udp_port()
    rrd = tmp_path / "overload.rrd"
    args = ["run", "--plant", "paper-continuous", "--gains", str(gains_path), "--mavlink", f"udpin:127.0.0.1:{port}"]
    args += ["--zenoh-listen", f"tcp/127.0.0.1:{free_tcp_port()}", "--no-truth", "--rrd", str(rrd), "--name", "ovl"]
    with Daemon("monitor", args, tmp_path / "monitor.log") as monitor:
        wait_ready(monitor)
        vehicle = Vehicle(port)
        for k in range(3):  # a monitor that keeps up answers every sample
            vehicle.send(k)
            assert vehicle.answered(k, timeout=10.0) == [k], monitor.log()[-2000:]
        assert _flood(monitor, vehicle, range(3, 23)) == [22], monitor.log()[-2000:]  # 19 shed
        assert _flood(monitor, vehicle, range(23, 33)) == [32], monitor.log()[-2000:]  # 9 more, the same episode
        wait_for(lambda: "no longer overloaded" in monitor.log(), 10, what="the overload episode's end")
        assert _flood(monitor, vehicle, range(33, 38)) == [37], monitor.log()[-2000:]  # a new episode: 4 shed
        # stopped for longer than a period: every queued sample is past its deadline, none is answered, and the
        # datagrams are not even parsed (counted from their headers)
        assert _flood(monitor, vehicle, range(38, 43), hold=1.2) == [], monitor.log()[-2000:]
        vehicle.send(43)
        assert vehicle.answered(43) == [43], monitor.log()[-2000:]
        assert monitor.stop() == 0, monitor.log()[-3000:]
        log = monitor.log()
    vehicle.sock.close()
    warnings = [line for line in log.splitlines() if "WARNING" in line and "overloaded:" in line]
    assert len(warnings) == 2, log[-3000:]
    assert "19 sample(s) shed (vehicle 7: 19)" in warnings[0] and "4 sample(s) shed (vehicle 7: 4)" in warnings[1]
    summary = next(line for line in log.splitlines() if "stopped:" in line)
    assert "shed 37," in summary and "shed per vehicle: 7: 37" in summary, summary
    assert "old datagrams (not parsed) 15," in summary, summary
    # the estimator predicted across exactly the shed samples: a shed sample is a lost sample
    assert "skipped 37," in summary and "samples processed 7," in summary, summary
    rows = load_recording(rrd).vehicles[SYSID].samples
    assert [r.k for r in rows] == [0, 1, 2, 22, 32, 37, 43]
    assert [r.shed for r in rows] == [0, 0, 0, 19, 28, 32, 37]


def test_a_monitor_running_a_third_of_the_time_stays_current(tmp_path: Path) -> None:
    """Three times more work than time to do it: a vehicle at 10 Hz while an outside script lets the monitor run
    0.1 s of every 0.3 s (SIGSTOP 0.2 s, SIGCONT). What was queued while it was stopped is answered only by the
    newest sample young enough; every answer arrives within one sample period of its sample; nothing is answered
    twice or out of order; everything not answered is counted as shed, and the estimator predicted across it."""
    h = 0.1
    plant = paper_plant_sampled_at(tmp_path / "plant-10hz.toml", h)
    gains = hand_made_gains_file(tmp_path / "gains-10hz.toml", str(plant))
    port = free_udp_port()
    args = ["run", "--plant", str(plant), "--gains", str(gains), "--mavlink", f"udpin:127.0.0.1:{port}"]
    args += ["--zenoh-listen", f"tcp/127.0.0.1:{free_tcp_port()}", "--no-truth", "--name", "third"]
    samples = 40
    with Daemon("monitor", args, tmp_path / "third.log") as monitor:
        wait_ready(monitor)
        assert monitor.proc is not None
        vehicle = Vehicle(port, h_us=int(h * 1e6))
        flying = threading.Event()

        def fly() -> None:
            start = time.monotonic()
            for k in range(1, samples):
                time.sleep(max(0.0, start + k * h - time.monotonic()))
                vehicle.send(k)
            flying.clear()

        vehicle.send(0)  # the vehicle is known before the monitor is first stopped
        assert vehicle.answered(0) == [0], monitor.log()[-2000:]

        flying.set()
        pilot = threading.Thread(target=fly, daemon=True)
        pilot.start()
        stops: list[float] = []  # monotonic instants the monitor was stopped
        try:
            while flying.is_set():  # the outside script: stopped two thirds of the time
                stops.append(time.monotonic())
                os.kill(monitor.proc.pid, signal.SIGSTOP)
                time.sleep(0.2)
                os.kill(monitor.proc.pid, signal.SIGCONT)
                vehicle.read(0.1)
        finally:
            os.kill(monitor.proc.pid, signal.SIGCONT)
            pilot.join(10)
        vehicle.read(0.5)
        assert monitor.stop() == 0, monitor.log()[-3000:]
        log = monitor.log()
    vehicle.sock.close()
    summary = next(line for line in log.splitlines() if "stopped:" in line)
    processed = int(re.search(r"samples processed (\d+)", summary).group(1))
    shed = int(re.search(r"shed (\d+),", summary).group(1))
    answered = vehicle.commands
    assert answered == sorted(set(answered)), answered  # never twice, never out of order
    assert len(answered) == processed, summary
    # the monitor really was short of time, and only what it did not answer is counted shed (a sample whose last
    # part came after a stop and was too old to be read is lost as incomplete instead)
    assert samples // 4 <= shed <= samples - processed, summary
    assert f"skipped {samples - 1 - answered[0] - (len(answered) - 1)}," in summary, summary
    # every answer within one sample period of its sample; a stop that lands between the decision to answer and
    # the send delays that answer by the stop, which no monitor can prevent (a slow machine spends longer on each
    # answer, so more stops land there): such an answer is excused only if a stop began while its sample was in the
    # monitor and it came within the stop's 0.2 s plus one period
    late = {k: rtt for k, rtt in vehicle.round_trips.items() if rtt > h}
    caught = {
        k
        for k, rtt in late.items()
        if rtt <= 0.2 + h and any(vehicle.sent_at[k] <= t <= vehicle.sent_at[k] + h for t in stops)
    }
    assert set(late) == caught and len(caught) <= len(stops) // 3, (late, stops, vehicle.round_trips)
    assert log.count("overloaded:") >= 1, log[-3000:]
