"""A simulated run written as a recording, the way ``fault-monitor run`` writes a live one.

Why: a notebook user who simulates a design wants the same post-analysis as for a flight (``replay``,
``report()``, the Rerun viewer) without daemons. Every sample becomes a ``SampleRecord`` (y, x_hat, f_hat,
u, residual as the estimator computed them) and a ``TruthRecord`` (state, fault, disturbance, true delay),
through the same recorder and layout, so ``fault-monitor replay FILE.rrd`` scores it like a live run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from monitor.model.closed_loop import Gains
from monitor.model.plant import Plant

__all__ = ["simulated_recording"]

SYSID = 1


@contextmanager
def simulated_recording(
    path: str | Path, plant: Plant, gains: Gains, method: str, scenario: str
) -> Iterator[Callable[..., None]]:
    """An ``on_sample`` callback for ``montecarlo.simulate`` that records every sample to ``path``; closed on exit."""
    from monitor import __version__
    from monitor.service.recorder import RrdRecorder
    from monitor.service.records import SampleRecord, TruthRecord
    from monitor.service.rrd_stream import recording_properties

    properties = {
        "monitor_version": __version__,
        "mode": f"simulated ({scenario})",
        **recording_properties(plant, gains, method),
    }
    recorder = RrdRecorder(path, application_id="fault-monitor simulate", properties=properties)

    def on_sample(
        k: int, x: np.ndarray, y: np.ndarray, step, u: np.ndarray, tau: float, f: np.ndarray, d: np.ndarray
    ) -> None:
        t = k * plant.h
        floats = lambda a: [float(v) for v in np.ravel(a)]  # noqa: E731
        recorder.submit(
            SampleRecord(
                sysid=SYSID,
                k=k,
                t=t,
                wall=t,
                y=floats(y),
                alpha=float(x[0]),
                q=float(x[1]) if plant.n > 1 else 0.0,
                elevator=float(u[0]),
                x_hat=floats(step.x_hat),
                f_hat=floats(step.f_hat),
                u=floats(u),
                residual=floats(step.residual),
                tau_obs=float(tau),
                processing_s=0.0,
                alarm=False,
            )
        )
        recorder.submit_truth(TruthRecord(sysid=SYSID, k=k, t=t, x=floats(x), f=floats(f), d=floats(d), tau=float(tau)))

    try:
        yield on_sample
    finally:
        recorder.close()
    if recorder.error:
        from monitor.errors import UserError

        raise UserError(f"{path}: the recording failed: {recorder.error}")
