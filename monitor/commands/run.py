"""``fault-monitor run``: the live FE/FTC service (see monitor/service/daemon.py for what it does)."""

from __future__ import annotations

import argparse

__all__ = ["register"]


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "run", help="the live monitor daemon: MAVLink in and out, estimates on Zenoh, optional .rrd recording",
        description=(
            "Listen for vehicles' MAVLink telemetry, run the observer and the fault-tolerant controller for each "
            "system id, answer with SET_ACTUATOR_CONTROL_TARGET, publish estimates and alarms on Zenoh "
            "(<prefix>/<sysid>/fault/estimate|alarm, queryable <prefix>/<sysid>/fault/status, liveliness "
            "<prefix>/monitor/<name>) and optionally record every sample to a Rerun .rrd. Stops on SIGINT/SIGTERM "
            "with exit code 0 after flushing the recording."),
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--plant", metavar="P", help="plant preset (paper, paper-continuous) or plant TOML file: the "
                   "default model for every vehicle the fleet file does not list")
    p.add_argument("--gains", metavar="GAINS.toml", help="gains file for --plant (from fault-monitor design)")
    p.add_argument("--force", action="store_true", help="run gains designed for another plant (hash mismatch)")
    p.add_argument("--fleet", metavar="FLEET.toml",
                   help="per-vehicle models: [vehicle.<sysid>] tables with plant = ... and gains = ...")
    p.add_argument("--mavlink", default="udpin:127.0.0.1:14550", metavar="udpin:HOST:PORT",
                   help="where to listen for vehicles (commands go back to each sample's sender)")
    p.add_argument("--signing-key", metavar="FILE", help="MAVLink 2 signing key (32 raw bytes, 64 hex digits or a "
                   "passphrase, as sim-vehicle): sign commands, reject unsigned or wrongly signed telemetry")
    p.add_argument("--rrd", metavar="FILE", help="record every processed sample to this Rerun file")
    p.add_argument("--name", help="monitor name in the liveliness key <prefix>/monitor/<name> (default: host-pid)")
    p.add_argument("--no-truth", dest="truth", action="store_false",
                   help="do not subscribe to <prefix>/*/truth (the simulator's ground truth, recorded beside f_hat)")
    p.add_argument("--alarm-threshold", type=float, default=1.0, metavar="X",
                   help="raise when max |f_hat| >= X (plant units) for --alarm-samples samples in a row")
    p.add_argument("--alarm-clear", type=float, default=0.5, metavar="Y",
                   help="clear when max |f_hat| < Y for --alarm-samples samples in a row")
    p.add_argument("--alarm-samples", type=int, default=2, metavar="N", help="persistence of raise and clear")
    p.add_argument("--vehicle-timeout", type=float, default=10.0, metavar="S",
                   help="forget a vehicle (its estimator state) after S seconds of silence")
    p.add_argument("--queue", type=int, default=10_000, metavar="N",
                   help="Zenoh hand-off queue length; estimates beyond it are dropped (counted), never waited for")
    from monitor.wire.zenoh_session import add_zenoh_arguments

    add_zenoh_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor import __version__
    from monitor.errors import UserError
    from monitor.service.alarm import AlarmConfig
    from monitor.service.daemon import MonitorConfig, default_name, run_daemon
    from monitor.service.udp_endpoint import parse_udpin
    from monitor.service.vehicles import Fleet, load_fleet, load_model
    from monitor.wire.zenoh_session import config_from_args

    if (args.plant is None) != (args.gains is None):
        raise UserError("--plant and --gains go together")
    if args.plant is None and args.fleet is None:
        raise UserError("give --plant and --gains, or --fleet FLEET.toml")
    try:
        alarm = AlarmConfig(args.alarm_threshold, args.alarm_clear, args.alarm_samples)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if not args.vehicle_timeout > 0:
        raise UserError("--vehicle-timeout must be positive")
    host, port = parse_udpin(args.mavlink)
    default = load_model(args.plant, args.gains, args.force) if args.plant else None
    fleet = load_fleet(args.fleet, default, args.force) if args.fleet else Fleet(default)
    key = None
    if args.signing_key:
        from monitor.wire.signing_key import load_signing_key  # one key-file format for both ends

        key = load_signing_key(args.signing_key)
    properties = {"monitor_version": __version__, "mavlink": args.mavlink, "key_prefix": args.key_prefix,
                  "alarm": f"threshold={alarm.threshold} clear={alarm.clear} samples={alarm.samples}"}
    if default is not None:
        properties.update(plant=default.plant.name, plant_hash=default.plant.digest, gains=str(args.gains),
                          gains_method=default.gains.method,
                          **{f"gain_{n}": str(getattr(default.gains.gains, n).tolist()) for n in
                             ("L", "M", "K1", "K2", "K3")})
    if args.fleet:
        properties["fleet"] = str(args.fleet)
    config = MonitorConfig(fleet=fleet, host=host, port=port, prefix=args.key_prefix, name=args.name or default_name(),
                           rrd=args.rrd, rrd_properties=properties, signing_key=key, alarm=alarm,
                           vehicle_timeout=args.vehicle_timeout, truth=args.truth, queue_max=args.queue)
    return run_daemon(config, config_from_args(args))
