"""A c172p flown by JSBSim itself and logged as MAVProxy logs, shared by the tests that identify a plant from
such a log: ``tests/test_identify.py`` (in process) and ``tests/e2e/test_identify_flight.py`` (the installed
commands); ``benchmarks/bench_identify.py`` times ``identify`` on the same flights.

The flight: c172p trimmed by JSBSim at 100 kt, 3000 ft; 5 s of trimmed flight, then an elevator PRBS of +-1 deg
about trim with random dwell 0.2-1 s for 60 s, integrated at 120 Hz and sampled at 20 Hz (h = 0.05 s). Each
sample is four MAVLink 2 records of a tlog (ATTITUDE, AOA_SSA, VFR_HUD, ACTUATOR_OUTPUT_STATUS, as sim-vehicle
sends them), stamped 2 ms apart, plus a HEARTBEAT a second: what MAVProxy writes.

Why the rotational integrators are set to Adams-Bashforth 2: JSBSim integrates the body rates and attitude by
forward Euler by default, which at 120 Hz takes ~9 % of the short period's damping away (measured: zeta 0.559
identified from the 120 Hz flight against 0.617 linearised; 0.586 at 240 Hz: an O(dt) loss). The identified
model is right about the aircraft JSBSim flew; to compare it with the continuous linearisation the flight must
be integrated accurately enough (AB2: zeta 0.597, 3 % off, the rest is JSBSim's alpha-dot lag and nonlinearity).
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
from dataclasses import dataclass
from pathlib import Path

import jsbsim
import numpy as np

H = 0.05
STEPS_PER_SAMPLE = 6  # 120 Hz
KT_TO_M_S = 1852.0 / 3600.0
T0_US = 1_700_000_000_000_000  # the tlog's wall clock at boot


@contextlib.contextmanager
def quiet():
    """JSBSim prints its banner and trim report on the C++ stdout (file descriptor 1)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as devnull:
        os.dup2(devnull.fileno(), 1)
        try:
            yield
        finally:
            import ctypes

            ctypes.CDLL(None).fflush(None)
            os.dup2(saved, 1)
            os.close(saved)


def trimmed_c172p(
    airspeed_kt: float = 100.0, altitude_ft: float = 3000.0, dt: float = H / STEPS_PER_SAMPLE, accurate: bool = True
):
    """A c172p instance trimmed in level flight by JSBSim's full trim."""
    with quiet():
        jsbsim.FGJSBBase().debug_lvl = 0
        fdm = jsbsim.FGFDMExec(None)
        fdm.set_debug_level(0)
        fdm.load_model("c172p")
        fdm.set_dt(dt)
        if accurate:  # see the module docstring
            fdm["simulation/integrator/rate/rotational"] = 3
            fdm["simulation/integrator/position/rotational"] = 3
        fdm["ic/h-sl-ft"] = altitude_ft
        fdm["ic/vc-kts"] = airspeed_kt
        fdm["ic/gamma-deg"] = 0.0
        fdm.run_ic()
        fdm["propulsion/set-running"] = -1
        fdm["simulation/do_simple_trim"] = 1
    return fdm


def prbs(n: int, amplitude: float, seed: int, dwell_s: tuple[float, float] = (0.2, 1.0), h: float = H) -> np.ndarray:
    """+-amplitude, switching after a random dwell of whole samples in ``dwell_s``."""
    rng = np.random.default_rng(seed)
    lo, hi = max(1, round(dwell_s[0] / h)), max(1, round(dwell_s[1] / h))
    out: list[float] = []
    sign = 1.0 if rng.random() < 0.5 else -1.0
    while len(out) < n:
        out += [sign * amplitude] * int(rng.integers(lo, hi + 1))
        sign = -sign
    return np.array(out[:n])


@dataclass
class Flight:
    """Per sample k: alpha deg, q rad/s, theta rad, airspeed m/s (calibrated, as VFR_HUD), elevator deg."""

    alpha: np.ndarray
    q: np.ndarray
    theta: np.ndarray
    airspeed: np.ndarray
    elevator: np.ndarray
    trim_elevator: float


def fly(
    seconds: float = 60.0,
    lead_in: float = 5.0,
    tail: float = 0.0,
    amplitude: float = 1.0,
    seed: int = 0,
    accurate: bool = True,
) -> Flight:
    """The c172p flown by JSBSim at 120 Hz with the PRBS on its elevator, sampled at 20 Hz."""
    fdm = trimmed_c172p(accurate=accurate)
    total = fdm["fcs/elevator-cmd-norm"] + fdm["fcs/pitch-trim-cmd-norm"]
    trim_deg = fdm["fcs/elevator-pos-deg"]
    fdm["fcs/pitch-trim-cmd-norm"] = 0.0  # the trim moves into the command: the surface stays put
    fdm["fcs/elevator-cmd-norm"] = total
    deg_per_command = trim_deg / total  # c172p: linear through 0 on each side (23 deg at +1, 28 deg at -1)
    lead, main, rest = round(lead_in / H), round(seconds / H), round(tail / H)
    du = np.concatenate([np.zeros(lead), prbs(main, amplitude, seed), np.zeros(rest)])
    rows = np.empty((len(du), 5))
    get = fdm.get_property_value
    for k, d in enumerate(du):
        rows[k, :4] = (
            get("aero/alpha-deg"),
            get("velocities/q-rad_sec"),
            get("attitude/theta-rad"),
            get("velocities/vc-kts") * KT_TO_M_S,
        )
        fdm["fcs/elevator-cmd-norm"] = total + d / deg_per_command
        fdm.run()
        rows[k, 4] = get("fcs/elevator-pos-deg")  # what the surface does over this sample (the FCS has no lag)
        for _ in range(STEPS_PER_SAMPLE - 1):
            fdm.run()
    return Flight(*rows.T, trim_elevator=trim_deg)


def write_tlog(
    path: Path, flight: Flight, *, hud: bool = True, sysid: int = 1, drop: float = 0.0, append: bool = False
) -> None:
    """One MAVLink 2 frame per record, 8-byte big-endian wall-clock microseconds first (MAVProxy's format).

    ``drop``: the share of records lost (seeded), as a lossy radio link loses them.
    """
    from monitor.wire.mavlink import mavlink, new_codec

    codec = new_codec(sysid, 1)
    stamp = struct.Struct(">Q")
    lose = np.random.default_rng(sysid)
    with open(path, "ab" if append else "wb") as fh:
        for k in range(len(flight.alpha)):
            t_us = k * round(H * 1e6)
            msgs = [
                mavlink.MAVLink_attitude_message(
                    t_us // 1000, 0.0, float(flight.theta[k]), 0.0, 0.0, float(flight.q[k]), 0.0
                ),
                mavlink.MAVLink_aoa_ssa_message(t_us, float(flight.alpha[k]), 0.0),
            ]
            if hud:
                msgs.append(
                    mavlink.MAVLink_vfr_hud_message(
                        float(flight.airspeed[k]), float(flight.airspeed[k]), 0, 60, 914.4, 0.0
                    )
                )
            msgs.append(
                mavlink.MAVLink_actuator_output_status_message(t_us, 1, [float(flight.elevator[k])] + [0.0] * 31)
            )
            if k % 20 == 0:
                msgs.append(mavlink.MAVLink_heartbeat_message(1, 3, 0, 0, 4, 3))
            for i, msg in enumerate(msgs):
                codec.send(msg)
                frame = codec.file.take()
                if not (drop and lose.random() < drop):
                    fh.write(stamp.pack(T0_US + t_us + i * 2000) + frame)
