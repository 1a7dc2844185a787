"""``fault-monitor run``: the live FE/FTC service (see monitor/service/daemon.py for what it does)."""

from __future__ import annotations

import argparse
import re

from monitor.checks import AUTO_MARGIN  # a constant of the light package module (no numpy at --help)
from monitor.wire import TURBULENCE_LEVELS

__all__ = [
    "register",
    "add_model_arguments",
    "load_models",
    "add_alarm_arguments",
    "alarm_from_args",
    "model_properties",
]


def model_properties(model, gains: str) -> dict[str, str]:
    """The recording's properties for the model that serves the vehicles (``run``'s default, ``analyse``'s)."""
    import json

    if model.envelope is not None:
        from monitor.service.rrd_stream import envelope_properties

        return {
            "plant": model.name,
            "plant_hash": model.digest,
            "gains": gains,
            "gains_method": str(model.envelope.gains.meta.get("method", "unknown")),
            "signals": model.signals.describe(),
            **envelope_properties(model.envelope),
        }
    out = {
        "plant": model.plant.name,
        "plant_hash": model.plant.digest,
        "gains": gains,
        "gains_method": model.gains.method,
        "signals": model.signals.describe(),
        **{f"gain_{n}": str(getattr(model.gains.gains, n).tolist()) for n in ("L", "M", "K1", "K2", "K3")},
    }
    if model.signals.operating_point is not None:  # y, x_hat, u, residual in the recording are deviations from it
        out["operating_point"] = json.dumps(model.signals.operating_point)
    return out


def add_model_arguments(p: argparse.ArgumentParser, fleet: bool = True) -> None:
    """The flags that say which plant, gains and signal map serve the vehicles (shared with ``analyse``)."""
    p.add_argument(
        "--plant",
        metavar="P",
        help="plant preset (paper, paper-continuous) or plant TOML file, or an envelope plant file (form = "
        '"envelope": the point is picked per sample from the measured schedule signals)'
        + (": the default model for every vehicle the fleet file does not list" if fleet else ""),
    )
    p.add_argument(
        "--gains",
        metavar="GAINS.toml",
        help="gains file for --plant (from fault-monitor design; an envelope's gains file for an envelope plant)",
    )
    p.add_argument(
        "--signals",
        metavar="FILE",
        help="signal map for --plant: a TOML file with a [signals] table "
        "naming the MAVLink fields of y, the actuator report and the command, and optionally the "
        "operating_point the plant was identified about (default: the plant file's "
        "own [signals], else the contract's AOA_SSA / ATTITUDE / ACTUATOR_OUTPUT_STATUS mapping)",
    )
    p.add_argument("--force", action="store_true", help="run gains designed for another plant (hash mismatch)")
    if fleet:
        p.add_argument(
            "--fleet",
            metavar="FLEET.toml",
            help="per-vehicle models: [vehicle.<sysid>] tables with plant, gains and optional signals",
        )


def load_models(args: argparse.Namespace, layouts=None):
    """The fleet from ``--plant/--gains/--signals`` and ``--fleet``; one-line errors for what is missing.

    ``layouts``: where signal maps look their message names up (default: the MAVLink dialect)."""
    from monitor.errors import UserError
    from monitor.service.fleet_file import Fleet, load_fleet, load_model

    fleet_file = getattr(args, "fleet", None)
    if (args.plant is None) != (args.gains is None):
        raise UserError("--plant and --gains go together")
    if args.plant is None and fleet_file is None:
        raise UserError("give --plant and --gains" + (", or --fleet FLEET.toml" if hasattr(args, "fleet") else ""))
    if args.signals and args.plant is None:
        raise UserError("--signals applies to --plant; in a fleet file give each vehicle a 'signals' key")
    from monitor.link.signals import MAVLINK

    default = load_model(args.plant, args.gains, args.force, args.signals, layouts or MAVLINK) if args.plant else None
    return load_fleet(fleet_file, default, args.force) if fleet_file else Fleet(default)


def _threshold_value(text: str) -> float | str:
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number or 'auto', got {text!r}") from None


def add_alarm_arguments(group) -> None:
    """The alarm's hysteresis flags (shared with ``analyse``, so a log is scored as the live run was)."""
    group.add_argument(
        "--alarm-threshold",
        type=_threshold_value,
        default=1.0,
        metavar="X",
        help="raise when max |f_hat| >= X (plant units) for --alarm-samples samples in a row; "
        f"'auto': {AUTO_MARGIN} x the proven bound on |f_hat| with no fault and |d| <= "
        "--disturbance-bound (fault-monitor threshold), so wind alone cannot raise it; or, "
        "with --turbulence, the level crossed once per flight hour in that turbulence "
        "(fault-monitor detectability) (default: 1.0)",
    )
    group.add_argument(
        "--disturbance-bound",
        type=float,
        default=None,
        metavar="D",
        help="with --alarm-threshold auto: the largest |d(k)| the vehicle meets (plant units)",
    )
    group.add_argument(
        "--turbulence",
        choices=TURBULENCE_LEVELS[1:],
        default=None,
        metavar="LEVEL",
        help="with --alarm-threshold auto, instead of --disturbance-bound: the turbulence flown "
        "(light, moderate, severe at 3000 ft; needs the plant's [disturbance] table)",
    )
    group.add_argument(
        "--calibration-log",
        action="append",
        default=None,
        metavar="LOG",
        help="with --alarm-threshold auto --turbulence LEVEL: a fault-free flight log in that turbulence (tlog, "
        "DataFlash or ULog; repeat for several), read by the same estimator; the threshold is raised to where "
        "the tail of its crossings puts the budget when the Gaussian prediction's tail is too thin. Tens of "
        "minutes of flight; the level flown must be LEVEL",
    )
    group.add_argument(
        "--alarm-clear",
        type=float,
        default=None,
        metavar="Y",
        help="clear when max |f_hat| < Y for --alarm-samples samples in a row (default: half the threshold)",
    )
    group.add_argument(
        "--alarm-samples", type=int, default=2, metavar="N", help="persistence of raise and clear (default: 2)"
    )


def alarm_from_args(args: argparse.Namespace, fleet=None):
    """The alarm configuration; ``auto`` needs the fleet's models (the bound of the worst one is used)."""
    import logging

    from monitor.errors import UserError
    from monitor.service.alarm import AlarmConfig

    threshold = args.alarm_threshold
    turbulence = getattr(args, "turbulence", None)
    calibration_logs = getattr(args, "calibration_log", None) or []
    if calibration_logs and (threshold != "auto" or turbulence is None):
        raise UserError("--calibration-log applies to --alarm-threshold auto --turbulence LEVEL only")
    from pathlib import Path

    for path in calibration_logs:  # before any work: a typo is one line, not a line after a minute of reading
        if not Path(path).is_file():
            raise UserError(f"--calibration-log {path}: no such log file")
    if threshold == "auto" and turbulence is not None:
        if args.disturbance_bound is not None:
            raise UserError(
                "--alarm-threshold auto takes one of --disturbance-bound D and --turbulence LEVEL, not both"
            )
        from monitor.checks.detectability import turbulence_threshold

        models = [p for m in fleet.models() for p in m.point_models()] if fleet else []  # an envelope: every point
        if not models:
            raise UserError("--alarm-threshold auto needs the vehicles' plant and gains")
        threshold = max(
            turbulence_threshold(
                m.plant, m.gains.gains, turbulence, report_time_constant=getattr(m.gains, "fault_time_constant", None)
            )
            for m in models
        )
        logging.getLogger("monitor.alarm").info(
            "alarm threshold auto: %.4g, crossed about once per flight hour in %s turbulence by a Gaussian f_hat "
            "(fault-monitor detectability)%s",
            threshold,
            turbulence,
            "" if calibration_logs else "; flights cross it more often (heavier tails): --calibration-log checks it",
        )
        if calibration_logs:
            from monitor.checks import FALSE_ALARMS_PER_HOUR
            from monitor.commands.alarm_calibration import calibrate_on_logs

            threshold, _calibration = calibrate_on_logs(calibration_logs, fleet, threshold, FALSE_ALARMS_PER_HOUR)
    elif threshold == "auto":
        if args.disturbance_bound is None:
            raise UserError(
                "--alarm-threshold auto needs --disturbance-bound D (the largest |d| to tolerate) or --turbulence LEVEL"
            )
        from monitor.checks.threshold import fault_threshold

        bounds = [
            fault_threshold(p.plant, p.gains.gains, args.disturbance_bound)
            for m in (fleet.models() if fleet else [])
            for p in m.point_models()
        ]
        if not bounds:
            raise UserError("--alarm-threshold auto needs the vehicles' plant and gains")
        worst = max(bounds, key=lambda b: b.threshold)
        threshold = AUTO_MARGIN * worst.threshold
        if not threshold > 0:
            raise UserError("--alarm-threshold auto: the proven bound is 0 (no disturbance reaches f_hat); give X")
        logging.getLogger("monitor.alarm").info(
            "alarm threshold auto: %.4g = %.2f x the proven bound %.4g on |f_hat| with no fault and |d| <= %g "
            "(the l1 norm at the worst constant delay is %.4g)",
            threshold,
            AUTO_MARGIN,
            worst.threshold,
            args.disturbance_bound,
            worst.frozen_l1 * args.disturbance_bound,
        )
    elif args.disturbance_bound is not None or turbulence is not None:
        raise UserError(
            f"--{'turbulence' if turbulence else 'disturbance-bound'} applies to --alarm-threshold auto only"
        )
    clear = args.alarm_clear if args.alarm_clear is not None else 0.5 * threshold
    try:
        return AlarmConfig(threshold, clear, args.alarm_samples)
    except ValueError as exc:
        raise UserError(str(exc)) from None


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run",
        help="the live monitor daemon: MAVLink in and out, estimates on Zenoh, optional .rrd recording",
        description=(
            "Receive vehicles' MAVLink telemetry (directly, or through MAVProxy, mavlink-router or an autopilot's "
            "TCP port), assemble one sample per sampling instant and system id, run the observer and the "
            "fault-tolerant controller, answer with SET_ACTUATOR_CONTROL_TARGET on the link the sample came from "
            "(not with --observe), tell ground stations (NAMED_VALUE_FLOAT FHAT, STATUSTEXT on alarms), publish "
            "estimates and alarms on Zenoh (<prefix>/<sysid>/fault/estimate|alarm, queryable "
            "<prefix>/<sysid>/fault/status, liveliness <prefix>/monitor/<name>) and optionally record every "
            "sample to a Rerun .rrd. Stops on SIGINT/SIGTERM with exit code 0 after flushing the recording."
        ),
        epilog="Example: fault-monitor run --plant paper-continuous --gains gains.toml "
        "--mavlink udpin:127.0.0.1:14550 --rrd run.rrd   (or: fault-monitor run --config monitor.toml)",
    )
    p.add_argument(
        "--config",
        metavar="FILE.toml",
        help="a TOML file whose keys are these long flag names "
        "(- or _; lists for repeatable flags, true/false for switches); flags given here override it",
    )
    add_model_arguments(p)
    link = p.add_argument_group("MAVLink")
    link.add_argument(
        "--mavlink",
        action="append",
        default=None,
        metavar="CONN",
        help="a connection as MAVProxy writes it: udpin:HOST:PORT (listen), udpout:HOST:PORT (send to a "
        "router; the monitor's 1 Hz HEARTBEAT makes it route vehicles back), tcp:HOST:PORT (connect, "
        "reconnect), tcpin:HOST:PORT (listen). Repeatable. Default: udpin:127.0.0.1:14550",
    )
    link.add_argument(
        "--observe",
        action="store_true",
        help="observe-only: the vehicle's own autopilot flies; send no commands, run the observer with "
        "the u(k) the vehicle reports in its actuator message",
    )
    link.add_argument(
        "--compensate",
        action="store_true",
        help="the vehicle's own autopilot flies and the monitor compensates: run the observer with the deflection "
        "the vehicle reports (as --observe) and answer each sample with the fault compensation alone (the "
        "deflection that cancels the estimated fault: -f_hat for an elevator bias), which the vehicle adds to its "
        "autopilot's deflection (sim-vehicle run --compensation). The estimator's error dynamics are certified; "
        "the loop with an autopilot the design never saw is not",
    )
    link.add_argument(
        "--no-gcs-feedback",
        dest="gcs_feedback",
        action="store_false",
        help="do not send NAMED_VALUE_FLOAT FHAT and alarm STATUSTEXT back on the vehicle's link",
    )
    link.add_argument(
        "--assembly-wait",
        type=float,
        default=0.02,
        metavar="S",
        help="how long a sample that is otherwise complete waits for the vehicle's actuator report "
        "(seconds; default: 0.02)",
    )
    link.add_argument(
        "--signing-key",
        metavar="FILE",
        help="MAVLink 2 signing key (32 raw bytes, 64 hex digits or a "
        "passphrase, as sim-vehicle): sign what the monitor sends, refuse unsigned or wrongly signed "
        "telemetry",
    )
    out = p.add_argument_group("outputs and alarm")
    out.add_argument("--rrd", metavar="FILE", help="record every processed sample to this Rerun file")
    out.add_argument(
        "--rerun-url",
        action="append",
        default=None,
        metavar="URL",
        help="also stream every sample live to the Rerun viewer at this gRPC address, as the viewer "
        "prints it (rerun+http://127.0.0.1:9876/proxy). Repeatable. A viewer that is slow or away "
        "loses its own oldest samples, never the loop's time nor --rrd's rows",
    )
    out.add_argument(
        "--rerun-spawn",
        action="store_true",
        help="start a local Rerun viewer (the 'rerun' executable, port 9876 on loopback; or use the one "
        "already there) and stream to it as --rerun-url does",
    )
    out.add_argument(
        "--name",
        help="monitor name in the liveliness key <prefix>/monitor/<name>, and with --group the member's name "
        "(default: host-pid)",
    )
    out.add_argument(
        "--no-truth",
        dest="truth",
        action="store_false",
        help="do not subscribe to <prefix>/*/truth (the simulator's ground truth, recorded beside f_hat)",
    )
    add_alarm_arguments(out)
    group = p.add_argument_group("monitor group")
    group.add_argument(
        "--group",
        metavar="NAME",
        help="join the monitor group NAME: several monitors (processes or machines) that all receive the fleet's "
        "telemetry (a router with one output per member) and share one Zenoh network. Each vehicle is answered "
        "(command, ground-station feedback, Zenoh estimate and alarm) by one member, chosen by rendezvous hashing "
        "of its system id over the live members; the others step its estimator on the same samples and stay "
        "silent, so that one takes over, f_hat going on without a reset, within 0.5 s of a member's last beat "
        "when it dies or hangs (liveliness <prefix>/monitor/group/NAME/<name>, beats every 0.1 s on "
        ".../<name>/beat). Members need distinct --name values. Estimates then name the member that answered "
        '("member"), and the recording marks each sample group/served. See the fleets guide',
    )
    out.add_argument(
        "--vehicle-timeout",
        type=float,
        default=10.0,
        metavar="S",
        help="forget a vehicle (its estimator state) after S seconds of silence (default: 10)",
    )
    out.add_argument(
        "--queue",
        type=int,
        default=10_000,
        metavar="N",
        help="estimates held for Zenoh within one round of the loop; beyond it they are dropped (counted), never "
        "waited for (default: 10000)",
    )
    from monitor.wire.zenoh_session import add_zenoh_arguments

    add_zenoh_arguments(p)
    p.set_defaults(func=run)


_KEY_CHUNK = re.compile(r"[A-Za-z0-9_.-]+")


def _free_tcp_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _live_viewers(args: argparse.Namespace) -> tuple[list[str], str | None]:
    """``--rerun-url`` checked and ``--rerun-spawn``'s executable found now: a typo is exit 2, not a silent sink."""
    from monitor.service.live_sinks import find_viewer, parse_viewer_url

    urls = list(args.rerun_url or [])
    for url in urls:
        parse_viewer_url(url)
    return urls, find_viewer() if args.rerun_spawn else None


def run(args: argparse.Namespace) -> int:
    from monitor import __version__
    from monitor.errors import UserError
    from monitor.link.transports import parse_connection
    from monitor.service.daemon import MonitorConfig, default_name, run_daemon
    from monitor.wire.zenoh_session import config_from_args

    if args.observe and args.compensate:
        raise UserError("--observe sends nothing and --compensate sends the compensation: choose one")
    if not args.vehicle_timeout > 0:
        raise UserError("--vehicle-timeout must be positive")
    if args.queue < 1:
        raise UserError("--queue must be at least 1")
    if not 0 <= args.assembly_wait < 10:
        raise UserError("--assembly-wait must be between 0 and 10 seconds")
    name = args.name or default_name()
    if args.group is not None:
        for flag, value in (("--group", args.group), ("--name", name)):
            if not _KEY_CHUNK.fullmatch(value):
                raise UserError(f"{flag} '{value}': use letters, digits, '-', '_' and '.' only (it is a Zenoh key)")
    connections = [parse_connection(c) for c in (args.mavlink or ["udpin:127.0.0.1:14550"])]
    live_urls, viewer = _live_viewers(args)
    fleet = load_models(args)
    if args.compensate and any(m.plant.lags is not None for m in fleet.models()):
        raise UserError(
            "--compensate needs delays shorter than a sample (the compensation's delay enters the model as "
            "B0(tau), B1(tau)); this plant's tau_max is one sample or more"
        )
    alarm = alarm_from_args(args, fleet)
    key = None
    if args.signing_key:
        from monitor.wire.signing_key import load_signing_key  # one key-file format for both ends

        key = load_signing_key(args.signing_key)
    if not args.zenoh_listen and not args.zenoh_config and args.zenoh_mode != "client":
        args.zenoh_listen = [f"tcp/127.0.0.1:{_free_tcp_port()}"]  # explicit, so the ready line can name it
    endpoints = ", ".join([f"listen {e}" for e in args.zenoh_listen] + [f"connect {e}" for e in args.zenoh_connect])
    properties = {
        "monitor_version": __version__,
        "mavlink": " ".join(str(c) for c in connections),
        "key_prefix": args.key_prefix,
        "mode": "compensate" if args.compensate else "observe" if args.observe else "control",
        "alarm": f"threshold={alarm.threshold} clear={alarm.clear} samples={alarm.samples}",
    }
    default = fleet.default
    if default is not None:
        properties.update(model_properties(default, str(args.gains)))
    if args.fleet:
        properties["fleet"] = str(args.fleet)
    if args.group is not None:
        properties.update(group=args.group, member=name)
    config = MonitorConfig(
        fleet=fleet,
        connections=connections,
        prefix=args.key_prefix,
        name=name,
        rrd=args.rrd,
        rrd_properties=properties,
        signing_key=key,
        alarm=alarm,
        vehicle_timeout=args.vehicle_timeout,
        truth=args.truth,
        queue_max=args.queue,
        observe=args.observe,
        compensate=args.compensate,
        gcs_feedback=args.gcs_feedback,
        assembly_wait=args.assembly_wait,
        zenoh_endpoints=endpoints,
        live_urls=live_urls,
        spawn_viewer=viewer,
        group=args.group,
    )
    return run_daemon(config, config_from_args(args))
