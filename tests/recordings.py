"""A hand-made recorded run, shared by the modules that need recordings without a live loop: the recorder's own
tests (``test_recorder``), ``replay`` on recordings (``test_replay``) and the live viewer's sink (``test_live_sinks``).

``make_run`` builds one vehicle's samples and truth (f steps to ``SIZE`` at ``ONSET``, f_hat follows ``LAG`` samples
later); ``write_run`` records several vehicles into an .rrd as a live loop would. The scores ``replay`` must give
follow from these constants.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

os.environ.setdefault("RERUN_ANALYTICS", "0")

from monitor.service.recorder import RrdRecorder  # noqa: E402
from monitor.service.records import SampleRecord, TruthRecord  # noqa: E402

ONSET, SIZE, LAG = 20, 2.0, 5


def make_run(
    sysid: int, n: int = 200, onset: int = ONSET, size: float = SIZE, lag: int = LAG, skip: frozenset[int] = frozenset()
) -> tuple[list[SampleRecord], list[TruthRecord]]:
    """A hand-made run: f steps to ``size`` at ``onset``, f_hat follows ``lag`` steps later, alarm with it.

    Every field differs per sample and per vehicle, so a misplaced row would be caught. Samples in
    ``skip`` were never received (the truth still has them); odd samples carry no elevator reading and
    sample 0 no observed delay, to exercise the optional fields.
    """
    samples, truth = [], []
    for k in range(n):
        f = size if k >= onset else 0.0
        truth.append(TruthRecord(sysid, k, 0.5 * k, [math.sin(k) + sysid, 0.1 * k], [f], [0.01 * k], 0.02 * (k % 23)))
        if k in skip:
            continue
        f_hat = size if k >= onset + lag else 0.0
        samples.append(
            SampleRecord(
                sysid=sysid,
                k=k,
                t=0.5 * k,
                wall=1.7e9 + 0.5 * k + 0.001 * sysid,
                y=[0.1 * k + sysid, -0.2 * k],
                alpha=math.sin(k / 7) * sysid,
                q=math.cos(k / 5),
                elevator=None if k % 2 else 0.3 * k,
                x_hat=[0.01 * k, 0.02 * k + sysid],
                f_hat=[f_hat],
                u=[-0.05 * k],
                residual=[1e-3 * k, -1e-3 * k],
                tau_obs=None if k == 0 else 0.01 * (k % 40),
                processing_s=1e-5 * (1 + k % 9),
                alarm=k >= onset + 3,
            )
        )
    return samples, truth


def write_run(
    path: Path, sysids: tuple[int, ...] = (1, 2), n: int = 200, truth: bool = True, **run: object
) -> dict[int, tuple[list[SampleRecord], list[TruthRecord]]]:
    """Record ``make_run`` for each vehicle, interleaved as a live loop would, and close the file."""
    runs = {s: make_run(s, n, **run) for s in sysids}
    with RrdRecorder(path, properties={"plant": "paper", "plant_hash": "abc123", "gains_L": "[[1.87], [1.63]]"}) as rec:
        for i in range(n):
            for s in sysids:
                samples, truths = runs[s]
                if i < len(samples):
                    rec.submit(samples[i])
                if truth:
                    rec.submit_truth(truths[i])
    return runs
