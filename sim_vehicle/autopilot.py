"""The vehicle's on-board autopilot: flies a mission's targets on any JSBSim aircraft, one JSBSim step at a time.

Why our own and not JSBSim's: JSBSim ships autopilot systems for a few aircraft only (c172x's ``c172ap``, c310's
``c310ap``, the generic ``systems/Autopilot.xml``), each with its own property names and gains, and c172p (the
aircraft this project flies most) has none. One Python autopilot, reading the same JSBSim properties on every
aircraft and writing JSBSim's normalised commands, flies every aircraft the same way, and a test can read its
structure and gains here rather than in an aircraft's XML.

Structure (every loop runs at JSBSim's own step, 1/120 s by default; angles in degrees, rates in deg/s):

* **Command shaping** (commands change smoothly between segments): the airspeed reference moves at most
  ``AIRSPEED_RATE_KT_S`` (1 kt/s) towards its target; the bank reference at most ``BANK_RATE_DEG_S`` (10 deg/s);
  the altitude reference moves towards an altitude target at most ``ALTITUDE_RATE_FPM`` (500 ft/min), slowing
  exponentially over its last ~50 ft (time constant ``ALTITUDE_APPROACH_S``), or at a segment's climb rate; the
  climb-rate reference itself changes by at most ``CLIMB_ACCEL_FPM_S`` (100 ft/min per second), so a climb
  starts and ends without a step in the pitch command.
* **Lateral**: bank hold on the aileron, a PD on the bank error with roll-rate damping, plus a slow integral
  that finds the aileron a steep turn needs against the aircraft's spiral tendency; heading hold is a bank
  command proportional to the heading error, limited to ``HEADING_BANK_LIMIT_DEG`` (30 deg), then shaped like
  any bank command. Yaw damper on the rudder: the yaw rate, washed out (``Gains.yaw_washout_s``) so that a steady
  turn's yaw rate is not opposed.
* **Airspeed on the throttle**: PI on calibrated airspeed (low-passed over ``Gains.airspeed_filter_s``) about the
  trim throttle, clamped to [0, 1]. The integral stops while the throttle sits on a stop and the error would push
  it further (anti-windup), and while the airspeed reference is still moving: the ramp's lag would wind it up
  and the aircraft overshoot the new airspeed (measured on c172p, slowing from 100 to 65 kt: 62.8 kt with the
  integral running, 64.9 kt with it held).
* **Vertical**: altitude -> flight path -> pitch attitude -> elevator. The altitude PI asks for a climb rate on
  top of the shaped one; as a flight-path angle (over the true airspeed), so that a fast aircraft does not get a
  stiffer altitude loop than a slow one. The pitch-attitude command is the trim attitude plus that flight-path
  angle, plus climb-rate feedback (``Gains.climb`` x the flight-path error), plus the turn's load-factor
  compensation ``Gains.turn`` x (n - 1) with n = 1/cos(bank): a banked aircraft needs a higher attitude to hold
  its altitude (c172p, 60 deg turn: altitude error 14 ft without it, 7 ft with it). Pitch attitude -> elevator: a
  PID on the attitude error with pitch-rate damping; the damping acts on the pitch rate in excess of a steady
  turn's (q_turn = g/V sin(bank) tan(bank)), which a level turn needs and a damper must not fight. The elevator
  starts at the trim deflection; the integral carries its slow changes (slower flight, turns).

Gains (``Gains``) are in normalised command units per unit of each command (aileron, rudder: [-1, 1]; throttle:
[0, 1]; the elevator per half of its travel, so that an aircraft with a smaller elevator travel gets smaller
deflections), and the surface gains are scheduled with dynamic pressure (the trim dynamic pressure over today's,
limited to [0.5, 2.5]): a slower aircraft needs larger deflections for the same moment. Tuned on c172p at 100 kt;
the same numbers fly the 737 at 250 kt, the T-6 Texan II at 160 kt and J3Cub at 60 kt (docs/missions.md).

The autopilot also watches for what the aircraft cannot do: ``Autopilot.trouble`` names a stall (alpha above the
aircraft's stall alpha for ``STALL_PERSISTENCE_S``), or a throttle held at a stop for ``THROTTLE_STOP_S`` (5 s)
while the airspeed error exceeds ``THROTTLE_STOP_ERROR_KT`` (5 kt) once the reference has stopped moving (a ramp's
lag is not a failure); that error is averaged over ``WATCH_AVERAGE_S`` (20 s), as JSBSim's turbulence moves the
airspeed by 5-10 kt for seconds at a time. An airspeed that still closes on the reference at ``PROGRESS_KT_S``
(0.2 kt/s, low-passed over 5 s) is no failure either: a low-powered aircraft (pa28) bleeds 30 kt in a 60-deg turn
and needs half a minute at full throttle to regain it. The flight model turns it into a one-line error.

Pure Python: it reads and writes JSBSim properties through any ``Properties`` object (an ``FGFDMExec`` is one),
so it never imports JSBSim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

__all__ = [
    "Properties",
    "Targets",
    "Gains",
    "Trim",
    "Autopilot",
    "AIRSPEED_RATE_KT_S",
    "ALTITUDE_RATE_FPM",
    "BANK_RATE_DEG_S",
    "CLIMB_ACCEL_FPM_S",
    "HEADING_BANK_LIMIT_DEG",
    "THROTTLE_STOP_S",
    "THROTTLE_STOP_ERROR_KT",
    "PROGRESS_KT_S",
    "STALL_PERSISTENCE_S",
]

G_FT_S2 = 32.174
AIRSPEED_RATE_KT_S = 1.0  # the airspeed reference moves at most this fast
ALTITUDE_RATE_FPM = 500.0  # the altitude reference moves towards an altitude target at most this fast
ALTITUDE_APPROACH_S = 6.0  # ... and slows down exponentially over its last 500 ft/min * 6 s / 60 = 50 ft
CLIMB_ACCEL_FPM_S = 100.0  # the climb-rate reference changes at most this fast (ft/min per second)
BANK_RATE_DEG_S = 10.0  # the bank reference moves at most this fast
HEADING_BANK_LIMIT_DEG = 30.0  # heading hold banks at most this much
THROTTLE_STOP_S = 5.0  # a throttle held at a stop this long ...
THROTTLE_STOP_ERROR_KT = 5.0  # ... while the airspeed error exceeds this: the aircraft cannot fly the segment
WATCH_AVERAGE_S = 20.0  # the watch averages the airspeed error over this long (gusts last seconds)
PROGRESS_KT_S = 0.2  # ... unless the airspeed still closes on the reference this fast (accelerating back after a turn)
PROGRESS_FILTER_S = 5.0  # that rate, low-passed over this long
STALL_PERSISTENCE_S = 0.5  # alpha above the stall alpha this long is a stall (not a gust's spike)
PITCH_LIMITS_DEG = (-15.0, 20.0)  # the pitch-attitude command stays within these


class Properties(Protocol):
    """Read and write JSBSim properties by name (``jsbsim.FGFDMExec`` is one)."""

    def __getitem__(self, name: str) -> float: ...
    def __setitem__(self, name: str, value: float) -> None: ...


@dataclass(frozen=True)
class Targets:
    """What a segment asks for: an airspeed, an altitude or a climb rate, a bank or a heading."""

    airspeed_kt: float
    altitude_ft: float | None = None
    climb_fpm: float | None = None
    bank_deg: float | None = None
    heading_deg: float | None = None


@dataclass(frozen=True)
class Gains:
    """The autopilot's gains (normalised command units, see the module's docstring); tuned on c172p."""

    bank: float = 0.06  # aileron per deg of bank error
    bank_i: float = 0.03  # aileron per deg s of bank error
    roll_rate: float = 0.02  # aileron per deg/s of roll rate
    heading: float = 1.0  # deg of bank per deg of heading error (then limited to HEADING_BANK_LIMIT_DEG)
    yaw_damper: float = 0.02  # rudder per deg/s of washed-out yaw rate
    yaw_washout_s: float = 1.0
    speed: float = 0.1  # throttle per kt
    speed_i: float = 0.012  # throttle per kt s
    airspeed_filter_s: float = 0.5  # the airspeed the throttle reads is low-passed with this time constant
    altitude: float = 0.056  # ft/s of climb rate per ft of altitude error
    altitude_i: float = 0.007  # ft/s per ft s
    climb: float = 5.3  # deg of pitch attitude per deg of flight-path error
    turn: float = 3.0  # deg of pitch attitude per unit of (n - 1)
    pitch: float = 0.06  # elevator (per half travel) per deg of attitude error
    pitch_i: float = 0.015  # per deg s
    pitch_rate: float = 0.02  # per deg/s of pitch rate (in excess of a steady turn's)


@dataclass(frozen=True)
class Trim:
    """Where the autopilot takes over: the trimmed aircraft's commands and state."""

    elevator_deg: float
    aileron: float
    rudder: float
    throttle: float
    theta_deg: float
    airspeed_kt: float
    altitude_ft: float
    qbar_psf: float


def _toward(value: float, target: float, step: float) -> float:
    """``value`` moved towards ``target`` by at most ``step``."""
    return target if abs(target - value) <= step else value + math.copysign(step, target - value)


def _clip(value: float, low: float, high: float) -> float:
    return low if value < low else high if value > high else value


def _wrap180(angle: float) -> float:
    """An angle in degrees brought into [-180, 180)."""
    return (angle + 180.0) % 360.0 - 180.0


class Autopilot:
    """Flies ``Targets`` from ``trim`` on; call ``step`` once per JSBSim step, before ``FGFDMExec.run``.

    ``step`` reads the aircraft's state from JSBSim, writes the aileron, rudder and throttle commands
    (``fcs/aileron-cmd-norm``, ``fcs/rudder-cmd-norm``, ``throttles``) and returns the elevator it wants as an
    absolute deflection in degrees; the flight model puts it on the surface through its servo (the compensation
    and the faults act there).
    """

    def __init__(
        self,
        trim: Trim,
        travel: tuple[float, float],
        dt: float,
        stall_alpha_deg: float,
        throttles: tuple[str, ...] = ("fcs/throttle-cmd-norm",),
        gains: Gains | None = None,
    ) -> None:
        self.trim = trim
        self.low, self.high = travel
        self.half_travel = (self.high - self.low) / 2.0
        self.dt = dt
        self.stall_alpha_deg = stall_alpha_deg
        self.throttles = throttles
        self.gains = gains or Gains()
        # the shaped references
        self.airspeed_ref = trim.airspeed_kt
        self.altitude_ref = trim.altitude_ft
        self.climb_ref = 0.0  # ft/min
        self.bank_ref = 0.0
        # the loops' memories
        self._bank_i = 0.0
        self._r_low = 0.0  # the yaw rate's low-passed part (what the washout removes)
        self._airspeed = trim.airspeed_kt  # the airspeed, low-passed (gusts are not the throttle's business)
        self._watched_error = 0.0  # the airspeed error, low-passed over THROTTLE_STOP_S (the watch's)
        self._progress = 0.0  # how fast the airspeed closes on its reference (kt/s), low-passed
        self._last_airspeed: float | None = None
        self._throttle_i = 0.0
        self._altitude_i = 0.0
        self._pitch_i = 0.0
        self._held: tuple[float, float] | None = None  # (elevator deg, throttle) held through an excite leg
        # what the watch has seen
        self._stalled_s = 0.0
        self._stop_s = 0.0
        self.trouble: tuple[str, str] | None = None  # (what it cannot do, why), e.g. ("stalls", "alpha ...")
        # the last commands (for the truth stream)
        self.elevator_deg = trim.elevator_deg
        self.throttle = trim.throttle
        self.pitch_cmd_deg = trim.theta_deg

    def step(
        self,
        fdm: Properties,
        targets: Targets,
        excitation_deg: float = 0.0,
        hold: bool = False,
        throttle_excitation: float = 0.0,
    ) -> float:
        """One JSBSim step: shape the references, run the loops, write aileron/rudder/throttle; the elevator (deg).

        ``hold`` (an identification leg, one with ``excite``): the throttle and the elevator stay where they were
        when the leg began and the PRBS is added to that elevator (and ``throttle_excitation``, a fraction of full
        throttle, to that throttle: a leg with ``excite_throttle``), while the lateral loops hold the segment's bank,
        as a test pilot holds stick and throttle through an identification manoeuvre. Why: with the pitch and
        airspeed loops closed, the throttle answers the PRBS, an input the identified model does not have (on
        c172p the one-trim model then read 1.9 deg of fault in the leg), and the loops filter the excitation.
        """
        if hold and self._held is None:
            self._held = (self.elevator_deg, self.throttle)
        elif not hold and self._held is not None:
            # the leg is over: the airspeed it lost (or gained) is taken back at the reference's own rate, from
            # where it is, as a pilot would (a reference left at the target would ask for it at once: c182 after
            # 30 s in a held 60 deg turn was 16 kt slow, and its throttle sat at full against a step)
            self._held = None
            self.airspeed_ref = fdm["velocities/vc-kts"]
            # ... and the altitude it drifted to, back to the target at the altitude reference's rates
            self.altitude_ref = fdm["position/h-sl-ft"]
            self.climb_ref = 60.0 * fdm["velocities/h-dot-fps"]
        g, dt = self.gains, self.dt
        phi, theta, psi = fdm["attitude/phi-deg"], fdm["attitude/theta-deg"], fdm["attitude/psi-deg"]
        p = math.degrees(fdm["velocities/p-rad_sec"])
        q = math.degrees(fdm["velocities/q-rad_sec"])
        r = math.degrees(fdm["velocities/r-rad_sec"])
        airspeed, vt_fps = fdm["velocities/vc-kts"], max(fdm["velocities/vt-fps"], 1.0)
        altitude, climb = fdm["position/h-sl-ft"], 60.0 * fdm["velocities/h-dot-fps"]
        qbar = fdm["aero/qbar-psf"]
        schedule = _clip(self.trim.qbar_psf / qbar, 0.5, 2.5) if qbar > 0 else 2.5

        # command shaping
        self.airspeed_ref = _toward(self.airspeed_ref, targets.airspeed_kt, AIRSPEED_RATE_KT_S * dt)
        if targets.climb_fpm is not None:
            wanted_climb = targets.climb_fpm
        else:
            target_ft = self.altitude_ref if targets.altitude_ft is None else targets.altitude_ft
            wanted_climb = _clip(
                60.0 * (target_ft - self.altitude_ref) / ALTITUDE_APPROACH_S, -ALTITUDE_RATE_FPM, ALTITUDE_RATE_FPM
            )
        self.climb_ref = _toward(self.climb_ref, wanted_climb, CLIMB_ACCEL_FPM_S * dt)
        self.altitude_ref += self.climb_ref / 60.0 * dt
        if targets.heading_deg is not None:
            bank_cmd = _clip(
                g.heading * _wrap180(targets.heading_deg - psi), -HEADING_BANK_LIMIT_DEG, HEADING_BANK_LIMIT_DEG
            )
        else:
            bank_cmd = targets.bank_deg or 0.0
        rolling = self.bank_ref != bank_cmd
        self.bank_ref = _toward(self.bank_ref, bank_cmd, BANK_RATE_DEG_S * dt)

        # lateral: bank hold on the aileron, yaw damper on the rudder
        bank_error = self.bank_ref - phi
        aileron = self.trim.aileron + schedule * (g.bank * bank_error - g.roll_rate * p) + self._bank_i
        if not rolling and (-1.0 < aileron < 1.0 or (aileron >= 1.0) != (bank_error > 0)):
            self._bank_i += schedule * g.bank_i * bank_error * dt
        fdm["fcs/aileron-cmd-norm"] = _clip(aileron, -1.0, 1.0)
        self._r_low += (r - self._r_low) * dt / g.yaw_washout_s
        rudder = self.trim.rudder + schedule * g.yaw_damper * (r - self._r_low)
        fdm["fcs/rudder-cmd-norm"] = _clip(rudder, -1.0, 1.0)

        # airspeed on the throttle
        self._airspeed += (airspeed - self._airspeed) * dt / g.airspeed_filter_s
        speed_error = self.airspeed_ref - self._airspeed
        throttle = self.trim.throttle + g.speed * speed_error + self._throttle_i
        ramping = self.airspeed_ref != targets.airspeed_kt
        held = self._held is not None  # the integrators hold too: the loops are open (no wind-up to release)
        if not ramping and not held and (0.0 < throttle < 1.0 or (throttle >= 1.0) != (speed_error > 0)):
            self._throttle_i += g.speed_i * speed_error * dt
        self.throttle = _clip(throttle if self._held is None else self._held[1] + throttle_excitation, 0.0, 1.0)
        for name in self.throttles:
            fdm[name] = self.throttle

        # vertical: altitude and climb rate -> pitch attitude -> elevator
        bank = math.radians(_clip(phi, -80.0, 80.0))
        load_factor = 1.0 / math.cos(bank)
        altitude_error = self.altitude_ref - altitude
        # the altitude PI asks for a climb rate (ft/s) on top of the shaped one; as flight-path angles, so that
        # a fast aircraft does not get a stiffer altitude loop than a slow one
        wanted_fps = self.climb_ref / 60.0 + g.altitude * altitude_error + self._altitude_i
        gamma_cmd = math.degrees(math.atan2(wanted_fps, vt_fps))
        gamma = math.degrees(math.atan2(climb / 60.0, vt_fps))
        pitch_cmd = self.trim.theta_deg + gamma_cmd + g.climb * (gamma_cmd - gamma) + g.turn * (load_factor - 1.0)
        low, high = PITCH_LIMITS_DEG
        if not held and (low < pitch_cmd < high or (pitch_cmd >= high) != (altitude_error > 0)):
            self._altitude_i += g.altitude_i * altitude_error * dt
        self.pitch_cmd_deg = pitch_cmd = _clip(pitch_cmd, low, high)
        pitch_error = pitch_cmd - theta
        q_turn = math.degrees(G_FT_S2 / vt_fps * math.sin(bank) * math.tan(bank))
        command = schedule * (g.pitch_rate * (q - q_turn) - g.pitch * pitch_error) - self._pitch_i
        elevator = self.trim.elevator_deg + self.half_travel * command
        # positive elevator pitches the nose down: a positive attitude error asks for less elevator
        if not held and (self.low < elevator < self.high or (elevator <= self.low) != (pitch_error > 0)):
            self._pitch_i += schedule * g.pitch_i * pitch_error * dt
        if self._held is not None:
            elevator = self._held[0]
        self.elevator_deg = _clip(elevator + excitation_deg, self.low, self.high)

        self._watch(fdm["aero/alpha-deg"], airspeed, targets, ramping or self._held is not None)
        return self.elevator_deg

    def _watch(self, alpha: float, airspeed: float, targets: Targets, ramping: bool) -> None:
        """Note a stall, or a throttle on a stop with the airspeed still off, once they have lasted. ``ramping``:
        the airspeed is not the throttle's to hold now (its reference moves, or an identification leg holds the
        throttle where it was), so an airspeed off the reference is no failure."""
        if self.trouble is not None:
            return
        self._stalled_s = self._stalled_s + self.dt if alpha > self.stall_alpha_deg else 0.0
        if self._stalled_s >= STALL_PERSISTENCE_S - 1e-9:
            self.trouble = (
                "stalls",
                f"alpha {alpha:.1f} deg, above its stall alpha {self.stall_alpha_deg:.1f} deg, "
                f"for {STALL_PERSISTENCE_S:g} s",
            )
            return
        stop = "full" if self.throttle >= 1.0 else "idle" if self.throttle <= 0.0 else None
        # while the reference still moves, a lagging airspeed is the ramp's, not a target the aircraft cannot hold;
        # the error is averaged over the watch's own window, so that a gust is not either
        self._watched_error += (self.airspeed_ref - airspeed - self._watched_error) * self.dt / WATCH_AVERAGE_S
        speed_error = self._watched_error
        if self._last_airspeed is not None:
            closing = (airspeed - self._last_airspeed) / self.dt * (1.0 if self.airspeed_ref > airspeed else -1.0)
            self._progress += (closing - self._progress) * self.dt / PROGRESS_FILTER_S
        self._last_airspeed = airspeed
        off = (
            stop is not None
            and not ramping
            and abs(speed_error) > THROTTLE_STOP_ERROR_KT
            and self._progress < PROGRESS_KT_S
        )
        self._stop_s = self._stop_s + self.dt if off else 0.0
        if self._stop_s >= THROTTLE_STOP_S - 1e-9:
            self.trouble = (
                f"cannot hold {targets.airspeed_kt:g} kt",
                f"throttle at {stop} for {THROTTLE_STOP_S:g} s, airspeed {airspeed:.1f} kt ({abs(speed_error):.1f} kt "
                f"{'below' if speed_error > 0 else 'above'} the reference over {WATCH_AVERAGE_S:g} s)",
            )
