"""``fault-monitor replay``: post-analysis of a monitor recording (.rrd), no viewer needed."""

from __future__ import annotations

import argparse
import json
from typing import Any

DESCRIPTION = """\
Read a recording written by `fault-monitor run --rrd FILE.rrd` and print, per vehicle:
  samples        how many samples the monitor processed (and how many k were never received)
  first alarm    the first sample with the fault alarm raised; its delay after the fault onset,
                 and how many alarms were raised before the onset (false alarms)
  settling       steps after the onset from which |f_hat - f| stays within 5 % of the fault size
  rms e_f        RMS of the estimation error f - f_hat (whole run, and after the onset)
  peak |alpha|   the largest angle of attack, deg
  delay, cpu     p50/p99/max of the delay the monitor observed and of its processing time

The true fault comes from the simulator's truth stream when the monitor recorded it (uav/<sysid>/truth);
otherwise give the fault SPEC the vehicle ran with, e.g. --fault bias:2@20 (same grammar as sim-vehicle).
Without either, settling and the estimation error are left out.

--json prints one object: the contract keys {"samples", "settling_steps", "rms_ef", "peak_alpha", ...}
at the top level, plus "vehicles": {"<sysid>": {same keys for that vehicle}}. With several vehicles the
top level is the fleet summary (samples and false alarms summed, the worst of the other scores); pick one
with --sysid N to get its scores at the top level.

To look at the same file interactively: rerun FILE.rrd   (opens on f_hat vs the true fault, alpha, q, u
and the delay). Exit code 2 (one line on stderr) for a missing, corrupt or non-fault-monitor file.
"""


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser(
        "replay",
        help="post-analysis of a recording: detection, settling, estimation error, delays (no viewer)",
        description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Example: fault-monitor replay run.rrd --fault bias:2@20 --json",
    )
    parser.add_argument("file", metavar="FILE.rrd", help="recording written by `fault-monitor run --rrd`")
    parser.add_argument("--json", action="store_true", help="print the analysis as one JSON object")
    parser.add_argument("--sysid", type=int, metavar="N", help="analyse only the vehicle with MAVLink system id N")
    parser.add_argument(
        "--fault",
        metavar="SPEC",
        help="the fault the vehicle ran with (bias:2@20, ramp:0.1@20, ...), used when the "
        "recording holds no truth stream",
    )
    parser.add_argument(
        "--tol",
        type=float,
        default=0.05,
        metavar="FRAC",
        help="settling band as a fraction of the fault size (default: 0.05)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monitor.errors import UserError
    from monitor.scoring import score_recording
    from monitor.service.recording_reader import load_recording

    if not 0 < args.tol < 1:
        raise UserError(f"--tol must be a fraction in (0, 1), got {args.tol}")
    if args.fault is not None:
        from monitor.wire.specs import parse_fault_spec

        parse_fault_spec(args.fault)  # a bad SPEC is one line before the file is read, truth or not
    report = score_recording(load_recording(args.file), sysid=args.sysid, fault_spec=args.fault, tol=args.tol)
    if args.json:
        print(json.dumps(report))
    else:
        print(format_report(report))
    return 0


def _num(value: float | None, unit: str = "", fmt: str = ".3g") -> str:
    return "n/a" if value is None else f"{value:{fmt}}{unit}"


def _stats(stats: dict[str, float] | None, scale: float, unit: str) -> str:
    if not stats:
        return "n/a"
    return (
        f"p50 {_num(stats['p50'] * scale, unit)}  p99 {_num(stats['p99'] * scale, unit)}  "
        f"max {_num(stats['max'] * scale, unit)}  (n={stats['n']})"
    )


def _vehicle_lines(v: dict[str, Any]) -> list[str]:
    lines = [f"vehicle {v['sysid']}: {v['samples']} samples"]
    if v["samples"]:
        lines[0] += (
            f", k {v['k_first']}..{v['k_last']} ({v['missing']} never received), "
            f"t {v['t_first']:.3f}..{v['t_last']:.3f} s"
        )
    if v["onset_k"] is not None:
        source = f"SPEC {v['fault_spec']}" if v["fault_source"] == "spec" else "the recorded truth"
        lines.append(f"  fault          size {_num(v['fault_size'])} from k={v['onset_k']} (from {source})")
    elif v["fault_source"]:
        lines.append(f"  fault          none in {v['fault_source']}")
    else:
        lines.append("  fault          unknown (no truth recorded; --fault SPEC scores settling and e_f)")
    if v["first_alarm_k"] is None:
        alarm = "never raised"
    else:
        alarm = f"k={v['first_alarm_k']} (t={_num(v['first_alarm_t'], ' s', '.3f')})"
        if v["detection_steps"] is not None:
            alarm += f"; detected {v['detection_steps']} steps ({_num(v['detection_s'], ' s')}) after onset"
    false = (
        "false alarms unknown (no truth, no --fault SPEC)"
        if v["false_alarms"] is None
        else f"{v['false_alarms']} false alarm(s) before onset"
    )
    lines.append(f"  first alarm    {alarm}; {false}")
    if v.get("fault_note"):
        lines.append(f"  note           {v['fault_note']}")
    if v["onset_k"] is not None:
        settle = (
            "never within the band"
            if v["settling_steps"] is None
            else f"{v['settling_steps']} steps ({_num(v['settling_s'], ' s')}) after onset"
        )
        lines.append(f"  settling       {settle} (band {v['settling_tol']:.0%} of the fault)")
    if v["rms_ef"] is not None:
        post = _num(v["rms_ef_after_onset"])
        lines.append(f"  rms e_f        {_num(v['rms_ef'])} (whole run), {post} after onset")
    lines.append(f"  peak |alpha|   {_num(v['peak_alpha'], ' deg')} (rms {_num(v['rms_alpha'], ' deg')})")
    lines.append(f"  delay observed {_stats(v['tau_obs_s'], 1.0, ' s')}")
    if v["tau_true_s"]:
        lines.append(f"  delay (truth)  {_stats(v['tau_true_s'], 1.0, ' s')}")
    lines.append(f"  processing     {_stats(v['processing_ms'], 1.0, ' ms')}")
    return lines


def format_report(report: dict[str, Any]) -> str:
    """The human-readable report: a header about the file, then one block per vehicle."""
    props = report["properties"]
    header = (
        f"recording {report['file']} ({report['application_id']}, fault-monitor "
        f"{props.get('fault_monitor_version', '?')}, rerun-sdk {props.get('rerun_sdk_version', '?')}, "
        f"{len(report['sysids'])} vehicle(s))"
    )
    lines = [header]
    if not report["complete"]:
        lines.append("  note: no footer (the writer did not close the file); the rows present were read")
    if not report["sysids"]:
        lines.append("no samples recorded")
    for v in report["vehicles"].values():
        lines.extend(_vehicle_lines(v))
    if len(report["sysids"]) > 1:
        lines.append(
            f"fleet: {report['samples']} samples, worst settling {_num(report['settling_steps'])} "
            f"steps, worst rms e_f {_num(report['rms_ef'])}, peak |alpha| "
            f"{_num(report['peak_alpha'], ' deg')}, {_num(report['false_alarms'])} false alarm(s)"
        )
    return "\n".join(lines)
