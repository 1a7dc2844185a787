"""``fault-monitor analyse FLIGHT.tlog``: observe-only estimation over a MAVLink telemetry log."""

from __future__ import annotations

import argparse
import json
import sys

__all__ = ["register"]


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "analyse",
        help="observe-only fault estimation over a flight log (.tlog, DataFlash .bin/.log, ULog .ulg), offline",
        description=(
            "Run the observer (eq. 5) over a flight's telemetry log as MAVProxy or QGroundControl write it "
            "(8-byte big-endian microsecond time + one MAVLink 1 or 2 frame per record), or over an ArduPilot "
            "on-board DataFlash log (.bin, or its text form .log; --signals names its messages, e.g. AOA.AOA, "
            "TimeUS is the clock) or a PX4 ULog log (.ulg; --signals names its topics, timestamp is the clock), "
            "with u(k) read from the vehicle's actuator report: the same assembler and "
            "estimator as 'run --observe'. Prints the report of 'fault-monitor replay' and what the log holds; "
            "--rrd also writes the recording in the same layout as 'run'."
        ),
        epilog="Example: fault-monitor analyse flight.tlog --plant paper-continuous --gains gains.toml "
        "--rrd flight.rrd --fault bias:2@20",
    )
    p.add_argument(
        "tlog", metavar="FLIGHT.tlog", help="the telemetry log (.tlog), a DataFlash log (.bin, .log) or a ULog (.ulg)"
    )
    from monitor.commands.run import add_alarm_arguments, add_model_arguments

    add_model_arguments(p, fleet=False)
    p.add_argument(
        "--sysid", type=int, metavar="N", help="analyse only this system id (default: every vehicle in the log)"
    )
    p.add_argument("--rrd", metavar="FILE", help="also write the recording (same layout as 'run', RECORDING.md)")
    p.add_argument(
        "--fault", metavar="SPEC", help="the fault the flight had, to score settling and e_f (e.g. bias:2@20)"
    )
    p.add_argument("--json", action="store_true", help="print the report as JSON (the shape of 'replay --json')")
    add_alarm_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from monitor import __version__
    from monitor.commands.replay import format_report
    from monitor.commands.run import alarm_from_args, load_models, model_properties
    from monitor.errors import UserError
    from monitor.scoring import score_recording
    from monitor.service.offline import analyse_log
    from monitor.service.recording_reader import Recording, VehicleSeries
    from monitor.wire.specs import parse_fault_spec

    if args.sysid is not None and not 1 <= args.sysid <= 255:
        raise UserError(f"--sysid must be a MAVLink system id 1-255, got {args.sysid}")
    if args.fault is not None:
        parse_fault_spec(args.fault)  # a bad SPEC is a one-line error before the work starts
    if not Path(args.tlog).is_file():
        raise UserError(f"{args.tlog}: no such log file")
    from monitor.link.onboard_log import open_onboard_log

    dlog = open_onboard_log(args.tlog)  # an on-board log (DataFlash or ULog), None for a tlog
    fleet = load_models(args, layouts=dlog.layouts if dlog is not None else None)
    alarm = alarm_from_args(args, fleet)
    model = fleet.default
    described = model_properties(model, str(args.gains))
    properties = {
        "monitor_version": __version__,
        "mode": "observe (analyse)",
        "source_log": str(args.tlog),
        **{k: described[k] for k in ("plant", "plant_hash", "gains", "gains_method", "signals")},
        "alarm": f"threshold={alarm.threshold} clear={alarm.clear} samples={alarm.samples}",
        **{k: v for k, v in described.items() if k == "operating_point" or k.startswith("envelope")},
    }
    recorder = None
    if args.rrd:
        from monitor.service.recorder import RrdRecorder

        recorder = RrdRecorder(args.rrd, properties=properties)

    def progress(fraction: float, samples: int) -> None:
        print(f"analyse: {fraction:.0%} of {args.tlog}, {samples} samples", file=sys.stderr, flush=True)

    try:
        if dlog is not None:
            from monitor.service.offline import analyse_dataflash

            result = analyse_dataflash(dlog, fleet, alarm, sysid=args.sysid, recorder=recorder, progress=progress)
        else:
            result = analyse_log(args.tlog, fleet, alarm, sysid=args.sysid, recorder=recorder, progress=progress)
    finally:
        if recorder is not None:
            recorder.close()
        if dlog is not None:
            dlog.close()
    if result.extra.get("commands_in_log"):
        print(
            f"analyse: note: the log holds {result.extra['commands_in_log']} SET_ACTUATOR_CONTROL_TARGET commands "
            "(a monitor-controlled flight); analyse reads the actuator report as the vehicle's own u(k) "
            "(observe-only), so its estimates are not those the live monitor computed",
            file=sys.stderr,
        )
    vehicles: dict[int, VehicleSeries] = {}
    for record in result.records:
        vehicles.setdefault(record.sysid, VehicleSeries(record.sysid)).samples.append(record)
    inventory = result.inventory
    if not vehicles:
        from monitor.link.log_inventory import why_no_samples

        sig = model.signals
        schedule = model.envelope.envelope.schedule if model.envelope is not None else ()
        names = tuple(dict.fromkeys((*sig.outputs, *sig.actuator, *schedule)))
        raise UserError(
            f"{args.tlog}: no sample could be assembled from {result.log_records} log records "
            f"({inventory.describe()}); " + why_no_samples(inventory, sig, names, args.sysid, model.plant.h)
        )
    recording = Recording(
        path=Path(args.rrd or args.tlog),
        application_id="fault-monitor analyse",
        properties={**properties, "fault_monitor_version": __version__},
        vehicles=vehicles,
        has_footer=True,
    )
    report = score_recording(recording, sysid=args.sysid, fault_spec=args.fault)
    report["log"] = {
        "records": result.log_records,
        "skipped_bytes": result.skipped_bytes,
        "truncated": result.truncated,
        "seconds": round(result.seconds, 3),
        **result.counts,
        "inventory": inventory.as_dict(),
    }
    if model.envelope is not None:
        from monitor.service.offline import envelope_report

        report["envelope"] = envelope_report(model.envelope, result.records)
    if args.json:
        print(json.dumps(report))
    else:
        print(format_report(report))
        c = result.counts
        print(
            f"log: {result.log_records} records in {result.seconds:.2f} s; {c['processed']} samples, "
            f"{c['incomplete']} incomplete, {c['garbage']} garbage, {result.skipped_bytes} bytes skipped"
            + (", truncated at the end" if result.truncated else "")
        )
        for line in inventory.lines():
            print(f"log holds: {line}")
        if "envelope" in report:
            from monitor.service.offline import envelope_lines

            for line in envelope_lines(report["envelope"]):
                print(line)
    return 0
