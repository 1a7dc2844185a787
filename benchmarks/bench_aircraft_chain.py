"""The chain on identified aircraft plants, timed (run by hand: python benchmarks/bench_aircraft_chain.py).

For each JSBSim aircraft and sample rate: an identification flight (a real sim-vehicle, logged as a tlog),
``identify`` (longitudinal, 4 states, 4 outputs), the default design, ``verify`` and ``threshold`` on it, and
optionally ``margin``. Prints the fit, the design's wall time and objective (a fast design that fell back to
H-infinity says so), verify's verdict, and the threshold per unit disturbance.

    python benchmarks/bench_aircraft_chain.py                    # c172p, c182, J3Cub at 20 and 50 Hz
    python benchmarks/bench_aircraft_chain.py --aircraft 737:200 --rates 20 --margin
"""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

from monitor.errors import UserError

DEFAULT = ("c172p:100", "c182:110", "J3Cub:60")  # NAME:AIRSPEED_KT, each at a speed it trims at


def _progress(text: str, final: bool = False) -> None:
    if final:
        print(f"  {text}", flush=True)


def run_one(name: str, airspeed: float, rate: float, work: Path, margin: bool) -> None:
    from monitor.checks.threshold import fault_threshold
    from monitor.checks.verify import verify_gains
    from monitor.demo.aircraft import record_identification_flight
    from monitor.demo.live import Aircraft
    from monitor.design import run_design
    from monitor.model.plant import load_plant
    from monitor.pipelines.identify_log import IdentifyRequest, identify_log

    altitude = 3000.0 if airspeed < 200 else 10000.0
    craft = Aircraft(name=name, airspeed=airspeed, altitude=altitude, rate=rate)
    tlog = work / f"{name}-{rate:g}.tlog"
    t = time.perf_counter()
    record_identification_flight(craft, "prbs:1:60", 0, 50.0, tlog, work / "logs", _progress)
    t_flight = time.perf_counter() - t
    plant_path = work / f"{name}-{rate:g}.toml"
    t = time.perf_counter()
    done = identify_log(IdentifyRequest(log=str(tlog), out=str(plant_path), model="longitudinal"))
    t_ident = time.perf_counter() - t
    plant = load_plant(str(plant_path))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t = time.perf_counter()
        result = run_design("certified", plant)
        t_design = time.perf_counter() - t
    v = verify_gains(plant, result.gains, result.certificate, result.gamma_e, result.gamma_z)
    t = time.perf_counter()
    bound = fault_threshold(plant, result.gains, 1.0)
    t_threshold = time.perf_counter() - t
    fit = min(done.result.fit_validation.values())
    print(
        f"{name:<6} {rate:>4g} Hz  fit >= {fit:5.1f} %  flight {t_flight:5.1f} s  identify {t_ident:4.1f} s  "
        f"design {t_design:5.1f} s ({result.objective}, gamma_e {result.gamma_e:.3f})  "
        f"verify {'stable' if v.stable else 'UNSTABLE'} rho {v.rho_max:.3f} cert {v.certificate_valid}  "
        f"threshold {bound.per_unit_disturbance:.4g}/|d| ({t_threshold:.1f} s)",
        flush=True,
    )
    if margin:
        from monitor.checks.margin import delay_margin

        t = time.perf_counter()
        m = delay_margin(plant, tolerance=plant.h / 20, curve_points=2, objective="fast")
        print(
            f"       margin tau_max {m.tau_max:.4f} s = {m.tau_max / plant.h:.2f} h ({time.perf_counter() - t:.1f} s)"
        )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--aircraft", nargs="*", default=list(DEFAULT), metavar="NAME:KT")
    p.add_argument("--rates", nargs="*", type=float, default=[20.0, 50.0], metavar="HZ")
    p.add_argument("--margin", action="store_true", help="also run margin (a bisection of designs: minutes)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        for spec in args.aircraft:
            name, _, kt = spec.partition(":")
            for rate in args.rates:
                try:
                    run_one(name, float(kt or 100), rate, Path(d), args.margin)
                except UserError as exc:  # an aircraft that does not trim, a log identify refuses: say so, go on
                    print(f"{name:<6} {rate:>4g} Hz  {exc}", flush=True)


if __name__ == "__main__":
    main()
