"""An experiment for the envelope work: a turn's gravity and kinematic terms as known inputs of a one-trim model.

Run by hand on a telemetry log of a mission and its truth (benchmarks/mission_fhat.py's vehicle, logged by any
recorder of its datagrams, with ``--truth-jsonl``):

    python benchmarks/turn_known_inputs.py --log man.tlog --truth truth.jsonl --plant P.toml --gains G.toml

It replays the log through the monitor's own estimator (observe-only, the longitudinal states alpha, q, theta,
airspeed in deg, deg/s, m/s) twice: as the monitor runs it, and with two terms that the telemetry measures added
to the model's prediction each sample (integrated over the sample with the plant's own dynamics):

* alpha-dot += (g / V) cos(theta) (cos(phi) - 1): the share of gravity a banked wing no longer carries;
* theta-dot += q (cos(phi) - 1) - r sin(phi): the Euler pitch rate, where the model has theta-dot = q.

It prints the largest |f_hat| per mission segment for both. The live loop has the same terms (a plant's
``[known_inputs]``, ``monitor.model.known_inputs``); this replay computes them with its own few lines, so that it
is an independent check of what the monitor reports with them.
"""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from monitor.gains import read_gains
from monitor.link.tlog import read_tlog
from monitor.model.discretize import integral_expm
from monitor.model.estimator import Estimator
from monitor.model.plant import load_plant
from monitor.wire.mavlink import new_codec, sample_index

G = 9.81


def samples(log: str, h: float) -> dict[int, dict[str, float]]:
    """Per sample k: alpha, q, theta, roll (rad), r (deg/s), airspeed (latest VFR_HUD), elevator."""
    rx = new_codec(255, 190)
    out: dict[int, dict[str, float]] = {}
    airspeed = None
    for _t_us, frame in read_tlog(log):
        for m in rx.parse_buffer(frame) or []:
            kind = m.get_type()
            if kind == "VFR_HUD":
                airspeed = m.airspeed
            elif kind == "AOA_SSA":
                out.setdefault(sample_index(m.time_usec, h), {})["alpha"] = m.AOA
            elif kind == "ATTITUDE":
                d = out.setdefault(round(m.time_boot_ms / (h * 1000)), {})
                d.update(q=math.degrees(m.pitchspeed), theta=math.degrees(m.pitch), roll=m.roll)
                d["r"] = math.degrees(m.yawspeed)
                if airspeed is not None:
                    d["airspeed"] = airspeed
            elif kind == "ACTUATOR_OUTPUT_STATUS":
                out.setdefault(sample_index(m.time_usec, h), {})["elevator"] = m.actuator[0]
    return {k: d for k, d in out.items() if len(d) == 7}


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--log", required=True)
    p.add_argument("--truth", required=True)
    p.add_argument("--plant", required=True, help="a longitudinal plant (alpha, q, theta, airspeed) from identify")
    p.add_argument("--gains", required=True)
    args = p.parse_args()
    plant = load_plant(args.plant)
    gains = read_gains(args.gains).gains
    op = plant.signals["operating_point"]
    y0 = [op["alpha"], op["q"], op["theta"], op["airspeed"]]
    assert plant.continuous is not None
    _, gamma = integral_expm(plant.continuous.A_c, plant.h)
    segment = {}
    for line in open(args.truth):
        d = json.loads(line)
        segment[d["k"]] = d.get("segment", "?")
    data = samples(args.log, plant.h)
    for known in (False, True):
        est = Estimator(plant, gains, u0=[op["elevator"]])
        state = est.initial_state()
        worst: dict[str, float] = {}
        for k in sorted(data):
            d = data[k]
            y = [d[name] - v for name, v in zip(("alpha", "q", "theta", "airspeed"), y0, strict=True)]
            result = est.observe(state, k, y, [d["elevator"] - op["elevator"]])
            if known:
                phi, theta, v = d["roll"], math.radians(d["theta"]), max(d["airspeed"], 10.0)
                terms = np.zeros(plant.n)
                terms[0] = math.degrees(G / v * math.cos(theta) * (math.cos(phi) - 1.0))
                terms[2] = d["q"] * (math.cos(phi) - 1.0) - d["r"] * math.sin(phi)
                state.z[: plant.n] += gamma @ terms
            name = segment.get(k, "?")
            worst[name] = max(worst.get(name, 0.0), abs(float(result.f_hat[0])))
        label = "with the turn's terms" if known else "as the monitor runs"
        print(f"{label:<22}", "  ".join(f"{n} {v:.2f}" for n, v in worst.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
