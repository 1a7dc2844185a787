"""``sim-vehicle``: a MAVLink vehicle daemon that flies the continuous plant, or a JSBSim aircraft, under delay,
faults and wind.

``sim-vehicle run`` is the only sub-command. It is the "real world" the monitor is tested against: the
monitor only sees what crosses the wire, while the exact truth goes to Zenoh ``<prefix>/<sysid>/truth``.
Errors the user can fix are one line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import logging
import sys

from monitor.cli_logging import add_log_level_everywhere, configure_logging
from monitor.config_file import parse_args_with_config
from monitor.errors import UserError, run_cli_command
from monitor.wire.zenoh_session import add_zenoh_arguments, close_quietly, config_from_args, key, open_session

__all__ = ["build_parser", "main"]

log = logging.getLogger("sim_vehicle")

EXAMPLES = """\
examples:
  # the paper's scenario, 100 samples at h = 1 s, 20 times faster than real time
  sim-vehicle run --plant paper-continuous --steps 100 --speedup 20 --fault bias:2@20

  # a rough link: 5 % loss, 2 % duplicates, 2 % reordering, normal delay, a signed link
  sim-vehicle run --delay normal:0.2:0.05 --loss 0.05 --duplicate 0.02 --reorder 0.02 --signing-key key.txt

  # a JSBSim Cessna 172 trimmed at 100 kt / 3000 ft, sampled at 20 Hz, in light turbulence, 10 minutes
  sim-vehicle run --aircraft c172p --rate 20 --turbulence light --steps 12000 --speedup 10 --fault bias:2@2000

  # an identification manoeuvre: +-1 deg PRBS about trim for 60 s (record it with MAVProxy, see
  # docs/tutorials/aircraft.md)
  sim-vehicle run --aircraft c172p --excite prbs:1:60 --steps 2400 --speedup 5 --no-zenoh

  # a mission: turns, a slow-down, a climb and a descent flown by the vehicle's own autopilot, the monitor's
  # commands added to its elevator as a compensation
  sim-vehicle run --aircraft c172p --mission docs/examples/mission-manoeuvres.toml --compensation --speedup 10

  # watch the ground truth from another terminal
  sim-vehicle run --zenoh-listen tcp/127.0.0.1:7447 &
  fault-monitor subscribe --zenoh-connect tcp/127.0.0.1:7447 'uav/*/truth'

SPECs: fault bias:2@20, bias:2@20-60 (end exclusive), ramp:0.1@20, loe:0.5@20, stuck@30, stuck:5@30,
joined by '+'; delay const:0.2, uniform:0:0.46, normal:0.2:0.05, trace:FILE; wind paper, none,
turbulence:SIGMA[:TAU]; excite prbs:AMP:SECONDS. With --aircraft, deflections and fault values are absolute
degrees of elevator (trim included). See sim_vehicle/README.md for the physics.
"""


def _version() -> str:
    """This package's version and the JSBSim it would fly (read from the metadata: JSBSim is not imported)."""
    from importlib import metadata

    try:
        mine = metadata.version("uav-fault-monitor")
    except metadata.PackageNotFoundError:  # pragma: no cover - a source tree without install
        from monitor import __version__ as mine
    try:
        jsbsim = f"JSBSim {metadata.version('jsbsim')}"
    except metadata.PackageNotFoundError:  # pragma: no cover
        jsbsim = "JSBSim not installed"
    return f"sim-vehicle {mine} ({jsbsim})"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="sim-vehicle",
        description="A simulated UAV (short-period pitch dynamics, or a JSBSim aircraft) speaking MAVLink 2: the "
        "vehicle fault-monitor is tested and demonstrated against. It publishes the exact truth on Zenoh "
        "for scoring.",
        epilog="Start with: sim-vehicle run --help",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    run = sub.add_parser(
        "run",
        help="fly a simulated aircraft: send MAVLink telemetry to a monitor, apply its elevator commands",
        description=(
            "Fly the continuous plant exactly (matrix exponentials between events), or a JSBSim aircraft\n"
            "(--aircraft, nonlinear 6-DOF, trimmed by JSBSim). Every sampling instant k*h the vehicle sends\n"
            "ATTITUDE + AOA_SSA + ACTUATOR_OUTPUT_STATUS (+ VFR_HUD for an aircraft; one datagram) to the monitor;\n"
            "a SET_ACTUATOR_CONTROL_TARGET answering sample k is applied when it arrives, after the emulated\n"
            "delay. The exact truth (state, fault, wind, delay) goes to Zenoh <prefix>/<sysid>/truth.\n"
            "Stops after --steps samples or on SIGINT/SIGTERM, prints a summary, exits 0."
        ),
        epilog=EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    run.add_argument("--config", metavar="FILE", help="TOML vehicle file whose keys preset these flags")
    g = run.add_argument_group("vehicle")
    g.add_argument(
        "--plant",
        default=None,
        metavar="P",
        help="continuous plant preset or TOML file (default: paper-continuous, unless --aircraft)",
    )
    g.add_argument("--sysid", type=int, default=1, metavar="N", help="MAVLink system id, 1..255 (default: 1)")
    g.add_argument(
        "--steps",
        type=int,
        default=None,
        metavar="N",
        help="number of samples to send, then exit (default: run until a signal)",
    )
    g.add_argument(
        "--speedup",
        type=float,
        default=1.0,
        metavar="S",
        help="simulated seconds per wall-clock second; delays scale too (default: 1)",
    )
    g.add_argument("--seed", type=int, default=0, metavar="N", help="seed of every random draw (default: 0)")
    g.add_argument("--fault", default=None, metavar="SPEC", help="elevator fault, e.g. bias:2@20 (default: none)")
    g.add_argument(
        "--wind",
        default=None,
        metavar="SPEC",
        help="the plant's wind: paper (oscillator, the default), none, or turbulence:SIGMA[:TAU]",
    )
    g.add_argument(
        "--sensor-noise",
        default=0.0,
        type=float,
        metavar="SIGMA",
        help="white noise added to the measured alpha and q, plant units (default: 0)",
    )
    g.add_argument("--x0", default=None, metavar="A,Q", help="initial state (default: 0)")
    g.add_argument(
        "--autopilot",
        default=None,
        metavar="K",
        help="fly with an on-board static gain u(k) = K y(k) (comma-separated, one per output), issued "
        "at sample k, reported in that sample's ACTUATOR_OUTPUT_STATUS and applied after the drawn delay; "
        "commands from outside are ignored. For observe-only monitoring (fault-monitor run --observe)",
    )
    g.add_argument(
        "--excite",
        default=None,
        metavar="SPEC",
        help="prbs:AMP:SECONDS: an identification manoeuvre flown on board, open loop: a seeded random "
        "binary sequence of trim +-AMP deg (dwell 0.2-0.8 s) for SECONDS, then trim; issued at each sample, "
        "reported in its ACTUATOR_OUTPUT_STATUS, applied after the drawn delay; commands from outside are "
        "ignored meanwhile",
    )
    a = run.add_argument_group("aircraft (JSBSim, nonlinear 6-DOF; instead of --plant)")
    a.add_argument(
        "--aircraft",
        default=None,
        metavar="NAME",
        help="fly this JSBSim aircraft (any JSBSim ships, e.g. c172p, 737, J3Cub; or your own with "
        "--aircraft-dir), trimmed in level flight; the elevator is an absolute deflection in degrees",
    )
    a.add_argument(
        "--aircraft-dir",
        default=None,
        metavar="DIR",
        help="where NAME is: a JSBSim root (DIR/aircraft/NAME/NAME.xml), a directory of aircraft "
        "(DIR/NAME/NAME.xml) or the aircraft's folder (DIR/NAME.xml)",
    )
    a.add_argument(
        "--airspeed", type=float, default=None, metavar="KT", help="trim airspeed, knots calibrated (default: 100)"
    )
    a.add_argument(
        "--altitude", type=float, default=None, metavar="FT", help="trim altitude, feet above sea level (default: 3000)"
    )
    a.add_argument(
        "--rate", type=float, default=None, metavar="HZ", help="sampling rate: telemetry every h = 1/HZ s (default: 20)"
    )
    a.add_argument(
        "--dt",
        type=float,
        default=None,
        metavar="S",
        help="JSBSim's integration step, made to divide h (default: 1/120 s, JSBSim's own)",
    )
    a.add_argument(
        "--turbulence",
        default=None,
        metavar="LEVEL",
        help="none, light, moderate or severe: JSBSim's MIL-F-8785C Dryden turbulence, seeded by --seed "
        "(default: none)",
    )
    a.add_argument(
        "--mission",
        default=None,
        metavar="FILE",
        help="fly a TOML timeline of [[segment]] tables (airspeed, altitude or climb, bank or heading, duration; "
        "docs/missions.md) on the vehicle's own autopilot, trimmed at the first segment; the run ends with the "
        "mission (or --steps). Not with --excite, --autopilot, --airspeed, --altitude",
    )
    a.add_argument(
        "--compensation",
        action="store_true",
        help="with --mission: an elevator command received (SET_ACTUATOR_CONTROL_TARGET, after its delay) is a "
        "compensation in degrees added to the autopilot's elevator; without it commands from outside are ignored",
    )
    n = run.add_argument_group("network (emulated on top of the real UDP path)")
    n.add_argument(
        "--delay",
        default=None,
        metavar="SPEC",
        help="total sensor->actuator delay in simulated seconds (default: uniform:0:0.46 for h = 1 s, "
        "i.e. uniform over [tau_min, min(0.46 h, tau_max)])",
    )
    n.add_argument(
        "--delay-split",
        default=0.5,
        type=float,
        metavar="R",
        help="share of the delay spent before the sample is sent (sensor->controller); the rest is "
        "the controller->actuator budget (default: 0.5)",
    )
    n.add_argument(
        "--loss", default=0.0, type=float, metavar="P", help="loss probability per datagram, both ways (default: 0)"
    )
    n.add_argument(
        "--duplicate", default=0.0, type=float, metavar="P", help="duplication probability per datagram (default: 0)"
    )
    n.add_argument(
        "--reorder",
        default=0.0,
        type=float,
        metavar="P",
        help="probability that a datagram is held ~1 sample so the next overtakes it (default: 0)",
    )
    m = run.add_argument_group("MAVLink")
    m.add_argument(
        "--mavlink",
        default="udpout:127.0.0.1:14550",
        metavar="udpout:HOST:PORT",
        help="where the monitor listens (default: udpout:127.0.0.1:14550); commands come back to "
        "the vehicle's own socket",
    )
    m.add_argument(
        "--bind",
        default="127.0.0.1:0",
        metavar="HOST:PORT",
        help="the vehicle's own socket (default: 127.0.0.1:0, an ephemeral loopback port)",
    )
    m.add_argument(
        "--signing-key",
        default=None,
        metavar="FILE",
        help="MAVLink 2 signing: 32 raw bytes, 64 hex digits or a passphrase (hashed with SHA-256 "
        "as MAVProxy does); unsigned, wrongly signed and replayed commands are rejected",
    )
    o = run.add_argument_group("outputs")
    o.add_argument("--no-zenoh", action="store_true", help="do not publish the truth on Zenoh")
    o.add_argument("--truth-jsonl", default=None, metavar="FILE", help="also write every truth payload to FILE")
    o.add_argument("--summary-json", default=None, metavar="FILE", help="also write the exit summary as JSON")
    add_zenoh_arguments(run)
    run.set_defaults(func=cmd_run)
    add_log_level_everywhere(parser)  # sim-vehicle --log-level L run, or sim-vehicle run --log-level L
    return parser


class FlightStopped(UserError):
    """The flight model could not go on (an aircraft that crashed or left JSBSim's envelope). Exit code 3."""

    exit_code = 3


def _flight_model(settings):
    """The aircraft, loaded and trimmed (a one-line error if it cannot be); None for the linear plant."""
    if settings.aircraft is None:
        return None
    from sim_vehicle.jsbsim_model import JSBSimFlightModel

    model = JSBSimFlightModel(settings.aircraft)
    trim, spec = model.trim, settings.aircraft
    log.info(
        "aircraft %s (JSBSim %s) trimmed at %.1f kt, %.0f ft: alpha %.3f deg, theta %.3f deg, elevator %.3f deg "
        "(travel %.2f..%.2f), throttle %.3f; dt %.6f s, h %.6f s, turbulence %s",
        spec.name,
        model.version,
        trim["airspeed_kt"],
        trim["altitude_ft"],
        trim["alpha_deg"],
        trim["theta_deg"],
        trim["elevator_deg"],
        *model.travel,
        trim["throttle"],
        model.dt,
        model.h,
        spec.turbulence,
    )
    return model


def cmd_run(args: argparse.Namespace) -> int:
    from sim_vehicle.config import settings_from_args
    from sim_vehicle.flight_model import FlightModelError
    from sim_vehicle.link import CommandDecoder, load_signing_key

    settings = settings_from_args(args)
    signing_key = load_signing_key(args.signing_key) if args.signing_key else None
    model = _flight_model(settings)  # before anything else opens: an aircraft that does not trim is one line
    session = publisher = None
    truth_key = key(args.key_prefix, settings.sysid, "truth")
    stopped: FlightModelError | None = None
    try:
        if not args.no_zenoh:
            session = open_session(config_from_args(args))
        from sim_vehicle.daemon import run_daemon
        from sim_vehicle.simulation import Simulation
        from sim_vehicle.truth import TruthPublisher

        truth = TruthPublisher(session, truth_key if session is not None else None, args.truth_jsonl)
        publisher = truth.publisher
        sim = Simulation(  # sink=None below: run_daemon plugs its UDP sink in before the first event
            plant=settings.plant,
            sink=None,  # type: ignore[arg-type]  # run_daemon plugs its UDP sink in before the first event
            sysid=settings.sysid,
            steps=settings.steps,
            fault=settings.fault,
            delay=settings.delay,
            wind=settings.wind,
            impairment=settings.impairment,
            delay_split=settings.delay_split,
            sensor_noise=settings.sensor_noise,
            seed=settings.seed,
            x0=settings.x0,
            autopilot=settings.autopilot,
            model=model,
            excite=settings.excite,
            compensation=settings.compensation,
        )
        weather = f"turbulence {settings.aircraft.turbulence}" if settings.aircraft else f"wind {args.wind or 'paper'}"
        mission = settings.aircraft.mission if settings.aircraft is not None else None
        log.info(
            "%s, fault %s, delay %s, %s, excite %s, mission %s%s, truth on %s",
            settings.vehicle,
            settings.fault,
            settings.delay,
            weather,
            settings.excite or "none",
            mission or "none",
            " (commands from outside: compensation)" if settings.compensation else "",
            truth_key if session is not None else "(no zenoh)",
        )
        decoder = CommandDecoder(settings.sysid, settings.h, signing_key)
        try:
            asyncio.run(
                run_daemon(
                    sim,
                    decoder,
                    truth,
                    target=settings.target,
                    bind=settings.bind,
                    speedup=settings.speedup,
                    key=signing_key,
                )
            )
        except OSError as exc:
            raise UserError(f"cannot use UDP socket {settings.bind[0]}:{settings.bind[1]}: {exc.strerror}") from None
        except FlightModelError as exc:
            stopped = exc
        finally:
            truth.close()
        print(sim.stats.summary(), flush=True)
        if args.summary_json:
            with open(args.summary_json, "w", encoding="utf-8") as fh:
                json.dump(
                    {"sysid": settings.sysid, "truth_published": truth.published, **sim.stats.as_dict()}, fh, indent=2
                )
    finally:
        close_quietly(session, publisher)
        if model is not None:
            model.close()
    if stopped is not None:
        raise FlightStopped(str(stopped))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parse_args_with_config(parser, argv)  # run --config FILE: the file presets the flags
    except UserError as exc:
        print(f"sim-vehicle: error: {exc}", file=sys.stderr)
        return exc.exit_code
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    configure_logging(args)
    return run_cli_command("sim-vehicle", args)
