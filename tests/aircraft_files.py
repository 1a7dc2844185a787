"""A linear aircraft about a non-zero operating point, shared by its offline tests
(``tests/test_link_aircraft_signals.py``) and its end-to-end flight (``tests/e2e/test_aircraft_link.py``).

The plant is a Cessna 172's longitudinal dynamics linearised by JSBSim (``AIRCRAFT_PLANT``, with the contract's
signal map ``SIGNALS`` and its operating point ``OP``/``Y0``/``U0``, elevator limit ``LIMIT``), ``GAINS`` are
certified gains for it copied from a design (a design takes ~10 s), and ``aircraft_files`` writes both files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monitor.design.result import DesignResult
from monitor.gains import write_gains
from monitor.model.closed_loop import Gains
from monitor.model.plant import parse_plant

# The contract's map, verbatim (what `fault-monitor identify` writes).
SIGNALS = """
[signals]
instant = "AOA_SSA"
outputs = ["alpha", "q", "theta", "airspeed"]
actuator = ["elevator"]
operating_point = { alpha = 2.31, q = 0.0, theta = 2.31, airspeed = 51.4, elevator = -4.3 }
[signals.measured]
alpha = { field = "AOA_SSA.AOA", unit = "deg" }
q = { field = "ATTITUDE.pitchspeed", scale = 57.29577951308232, unit = "deg/s" }
theta = { field = "ATTITUDE.pitch", scale = 57.29577951308232, unit = "deg" }
airspeed = { field = "VFR_HUD.airspeed", unit = "m/s" }
elevator = { field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }
[signals.command]
message = "SET_ACTUATOR_CONTROL_TARGET"
channels = [1]
full_scale = [30.0]
group = 0
"""
OP = {"alpha": 2.31, "q": 0.0, "theta": 2.31, "airspeed": 51.4, "elevator": -4.3}
Y0 = np.array([OP["alpha"], OP["q"], OP["theta"], OP["airspeed"]])
U0 = OP["elevator"]
LIMIT = 25.0

# A Cessna 172's longitudinal dynamics linearised by JSBSim at 90 kt (alpha deg, q deg/s, theta deg,
# airspeed; elevator deg), h = 0.05 s; the elevator bias is the fault.
AIRCRAFT_PLANT = (
    """
form = "continuous"
name = "c172p-lin"
h = 0.05
tau_min = 0.0
tau_max = 0.023
A_c = [
    [-3.0276990713444287, 0.956160252189708, 8.939810667361824e-08, -0.1965633428409076],
    [-33.79865243110685, -5.631247263779725, 2.0403540696098972e-05, 0.7661273368953734],
    [0.0, 0.9999998103612071, 0.0, 0.0],
    [0.05186089519311677, -0.00017304549230364664, -0.33171493596061413, -0.06105672471407935],
]
B_c = [[-0.1990410912425061], [-22.750700723739623], [0.0], [-0.05133781351524741]]
D_cf = [[-0.1990410912425061], [-22.750700723739623], [0.0], [-0.05133781351524741]]
D_cd = [[-3.0276990713444287], [-33.79865243110685], [0.0], [0.05186089519311677]]
C = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]

[actuator]
limit = 25.0
"""
    + SIGNALS
)

# Certified (fast objective) gains for that plant, from `fault-monitor design` (copied: a design takes ~10 s).
GAINS = Gains(
    L=np.array(
        [
            [0.003314603030433173, 0.09897908009875855, 0.0026141136345877716, 0.0002492380334806095],
            [0.05609239187170379, 1.675004004106868, 0.0442381440679786, 0.004217807476480867],
            [0.0031628891216548063, 0.09444867238742932, 0.002494462082395018, 0.00023783006820440717],
            [0.00014534474277291712, 0.004340214742087519, 0.00011462840958927175, 1.0929042643375828e-05],
        ]
    ),
    M=np.array([[-0.03440933366142443, -1.0275149577033802, -0.02713746034005597, -0.002587373081002338]]),
    K1=np.array([[-0.2312986630787076, 0.042381898764746406, 0.19924310720296023, -0.1136696475876337]]),
    K2=np.array([[0.7393642343241376]]),
    K3=np.array([[-0.2606357656758624]]),
)


def aircraft_files(directory: Path, plant_text: str = AIRCRAFT_PLANT) -> tuple[Path, Path]:
    """The plant file (with its [signals] table) and a gains file stamped with its hash."""
    plant_path, gains_path = directory / "c172p-lin.toml", directory / "c172p-gains.toml"
    plant_path.write_text(plant_text)
    plant = parse_plant(plant_text, str(plant_path))
    write_gains(
        gains_path,
        DesignResult(
            method="certified", gains=GAINS, gamma_e=0.0, gamma_z=0.0, build_seconds=0, solve_seconds=0, total_seconds=0
        ),
        plant,
    )
    return plant_path, gains_path
