"""Benchmark of reading a PX4 ULog log (run by hand; prints figures): pyulog's parse, the merge of the topics
into one time-ordered stream, and the samples assembled with derived signals (α from the NED velocity and the
attitude quaternion), against the same flight as a tlog of ATTITUDE, LOCAL_POSITION_NED, WIND_COV and
ACTUATOR_OUTPUT_STATUS read with the same derived map.

The flight is ``tests/px4_flight.py``'s c172p (JSBSim at 200 Hz, 50 Hz samples), logged at the high-rate
profile's rates: seven topics, eight instances.

    /work/venv/bin/python benchmarks/bench_ulog.py [--minutes 1 10] [--repeat 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from tests.derived_maps import MAVLINK_MAP  # noqa: E402
from tests.px4_flight import H, fly, write_mavlink_tlog, write_px4_ulog  # noqa: E402 - found through sys.path
from tests.readme_blocks import file_block  # noqa: E402


def read_ulog(path: Path) -> tuple[float, float, int, int]:
    """(seconds parsing with pyulog, seconds merging and assembling, records, samples)."""
    from monitor.link.flight_log import read_flight
    from monitor.link.onboard_log import open_onboard_log
    from monitor.pipelines.identify_log import map_for

    t = time.perf_counter()
    log = open_onboard_log(path)
    parsed = time.perf_counter() - t
    assert log is not None
    table = tomllib.loads(file_block("px4-fixed-wing.toml").text)["signals"]
    smap, _written = map_for(table, "px4", ("alpha", "q", "theta", "airspeed"), log.layouts)
    t = time.perf_counter()
    rows = read_flight(str(path), smap, H, dataflash=log).samples[1]
    return parsed, time.perf_counter() - t, log.inventory.records, len(rows)


def read_tlog(path: Path) -> tuple[float, int]:
    from monitor.link.flight_log import read_flight
    from monitor.link.signals import parse_signals

    smap = parse_signals(tomllib.loads(MAVLINK_MAP)["signals"], "mavlink", 1, 1)
    t = time.perf_counter()
    rows = read_flight(str(path), smap, H).samples[1]
    return time.perf_counter() - t, len(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="bench-ulog-"))
    for minutes in args.minutes:
        flight = fly(60.0 * minutes, lead_in=5.0, wind_ned_fps=(10.0, -10.0, 0.0))
        ulg, tlog = work / f"flight-{minutes:g}min.ulg", work / f"flight-{minutes:g}min.tlog"
        write_px4_ulog(ulg, flight)
        write_mavlink_tlog(tlog, flight)
        ulog_runs = [read_ulog(ulg) for _ in range(args.repeat)]
        tlog_runs = [read_tlog(tlog) for _ in range(args.repeat)]
        parse = statistics.median(r[0] for r in ulog_runs)
        assemble = statistics.median(r[1] for r in ulog_runs)
        records, samples = ulog_runs[0][2], ulog_runs[0][3]
        tlog_s = statistics.median(r[0] for r in tlog_runs)
        print(
            f"{minutes:g} min: ULog {ulg.stat().st_size / 1e6:.1f} MB, {records} records: pyulog parse {parse:.2f} s, "
            f"merge + assemble {assemble:.2f} s ({records / (parse + assemble) / 1e3:.0f} k records/s), "
            f"{samples} samples; tlog {tlog.stat().st_size / 1e6:.1f} MB: {tlog_s:.2f} s, {tlog_runs[0][1]} samples"
        )


if __name__ == "__main__":
    main()
