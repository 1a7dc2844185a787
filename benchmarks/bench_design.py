"""Design build and solve times per method and preset (run by hand: python benchmarks/bench_design.py).

Prints, for each design: cvxpy problem construction, solve time (for `certified`: the controller search
plus the certificate's Clarabel solves), total wall time, and the bound reached. Also the cvxpy import time,
which every design pays once per process.
"""

from __future__ import annotations

import time
import warnings

t0 = time.perf_counter()
import cvxpy  # noqa: E402,F401

IMPORT_S = time.perf_counter() - t0

from monitor.design import run_design  # noqa: E402
from monitor.model.plant import load_plant  # noqa: E402

DESIGNS = (
    ("certified (fast)", "certified", {}),
    ("certified (hinf)", "certified", {"objective": "hinf"}),
    ("certified, max-losses 3", "certified", {"max_losses": 3}),
    ("paper", "paper", {}),
    ("separate", "separate", {}),
    ("robust-separate", "robust-separate", {}),
)


def main(repeats: int = 3) -> None:
    print(f"cvxpy import: {IMPORT_S:.2f} s")
    print(f"{'plant':<18}{'method':<24}{'build s':>9}{'solve s':>9}{'total s':>9}{'gamma_e':>9}")
    for preset in ("paper", "paper-continuous"):
        plant = load_plant(preset)
        for label, method, options in DESIGNS:
            best = None
            for _ in range(repeats):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    r = run_design(method, plant, **options)
                if best is None or r.total_seconds < best.total_seconds:
                    best = r
            print(
                f"{preset:<18}{label:<24}{best.build_seconds:>9.3f}{best.solve_seconds:>9.3f}"
                f"{best.total_seconds:>9.3f}{best.gamma_e:>9.4f}"
            )


if __name__ == "__main__":
    main()
