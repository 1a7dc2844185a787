"""What recording costs the live loop: ``RrdRecorder.submit`` per sample, the writer's cost, and ``close``.

Run: ``python benchmarks/bench_recorder.py [--samples 10000] [--vehicles 1]``. Three figures:

* submit, burst: p50/p99/max of one ``submit`` while the writer thread flushes behind it (the cost the
  loop pays, GIL contention included);
* writer: the background cost per sample of turning records into columns and ``send_columns`` (how
  far below the loop's rate the writer stays, i.e. why the unbounded buffer does not grow);
* close: flushing what is left, the blueprint and the footer;
* paced (``--rate``): a stand-in loop (a few small matrix products per sample, like the observer)
  at a fixed rate, timed per sample with and without the recorder: the latency the writer's share of
  the GIL adds to the loop.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("RERUN_ANALYTICS", "0")

from monitor.service.recorder import RrdRecorder  # noqa: E402
from monitor.service.records import SampleRecord  # noqa: E402


def samples(n: int, vehicles: int) -> list[SampleRecord]:
    """``n`` paper-sized samples (2 states, 1 fault, 1 input, 2 outputs: 14 scalars) spread over ``vehicles``."""
    out = []
    for i in range(n):
        k, sysid = divmod(i, vehicles)
        out.append(
            SampleRecord(
                sysid + 1,
                k,
                0.01 * k,
                time.time(),
                [0.1, 0.2],
                0.1,
                0.2,
                0.3,
                [1.0, 2.0],
                [0.5],
                [0.3],
                [0.01, 0.02],
                0.2,
                5e-5,
                False,
            )
        )
    return out


def burst(path: Path, recs: list[SampleRecord]) -> tuple[np.ndarray, float]:
    rec = RrdRecorder(path)
    costs = np.empty(len(recs))
    for i, r in enumerate(recs):
        t0 = time.perf_counter_ns()
        rec.submit(r)
        costs[i] = time.perf_counter_ns() - t0
    t0 = time.perf_counter()
    rec.close()
    return costs / 1e3, time.perf_counter() - t0


def writer_cost(path: Path, recs: list[SampleRecord], batch: int) -> float:
    """Seconds per sample of the writer's step (records -> columns -> ``send_columns``), ``batch`` at a time."""
    rec = RrdRecorder(path, batch_size=10**9, max_age_s=1e9)  # the thread never flushes: we drain by hand
    spent = 0.0
    for start in range(0, len(recs), batch):
        for r in recs[start : start + batch]:
            rec.submit(r)
        t0 = time.perf_counter()
        rec._drain()  # noqa: SLF001 - measuring the writer's step on its own
        spent += time.perf_counter() - t0
    rec.close()
    return spent / len(recs)


def paced(path: Path | None, recs: list[SampleRecord], rate: float) -> np.ndarray:
    """Per-sample time (us) of a stand-in loop step + ``submit`` at ``rate`` samples/s (None: no recorder)."""
    rec = RrdRecorder(path) if path is not None else None
    a, x = np.eye(2) * 0.9, np.ones(2)
    period = 1.0 / rate
    costs = np.empty(len(recs))
    start = time.perf_counter()
    for i, r in enumerate(recs):
        while time.perf_counter() < start + i * period:
            pass
        t0 = time.perf_counter_ns()
        for _ in range(4):
            x = a @ x + 0.1  # the observer/controller's handful of 2x2 products
        if rec is not None:
            rec.submit(r)
        costs[i] = time.perf_counter_ns() - t0
    if rec is not None:
        rec.close()
    return costs / 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=10_000)
    parser.add_argument("--vehicles", type=int, default=1)
    parser.add_argument("--rate", type=float, default=5000.0, help="paced loop rate, samples/s (0: skip)")
    args = parser.parse_args()
    recs = samples(args.samples, args.vehicles)
    with tempfile.TemporaryDirectory() as tmp:
        costs, close_s = burst(Path(tmp) / "burst.rrd", recs)
        size = (Path(tmp) / "burst.rrd").stat().st_size
        loop = (
            {"without": paced(None, recs, args.rate), "with": paced(Path(tmp) / "paced.rrd", recs, args.rate)}
            if args.rate
            else {}
        )
        writer = {b: writer_cost(Path(tmp) / f"writer{b}.rrd", recs, b * args.vehicles) for b in (64, 256, 1024)}
    p50, p99 = np.percentile(costs, [50, 99])
    print(f"rerun-sdk recorder, {args.samples} samples over {args.vehicles} vehicle(s), 14 scalars/sample")
    print(f"submit   p50 {p50:.2f} us  p99 {p99:.2f} us  max {costs.max():.0f} us  (writer thread flushing behind)")
    for b, cost in writer.items():
        print(
            f"writer   {cost * 1e6:.1f} us/sample in the background, {b} samples/vehicle a flush "
            f"({1 / cost:,.0f} samples/s)"
        )
    for label, c in loop.items():
        q50, q99 = np.percentile(c, [50, 99])
        print(
            f"paced    {args.rate:,.0f}/s {label:>7} recorder: step p50 {q50:.1f} us  p99 {q99:.1f} us  "
            f"max {c.max():.0f} us"
        )
    print(f"close    {close_s * 1e3:.1f} ms (rest of the buffer, blueprint, footer); file {size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
