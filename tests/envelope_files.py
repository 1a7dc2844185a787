"""Plants at several operating points, for the envelope's tests (``tests/test_envelope.py``) and its benchmark.

``aircraft_at(V)``: the Cessna 172 longitudinal model of ``tests/aircraft_files.py`` (linearised at 51.4 m/s) moved
to airspeed V the way its dimensional derivatives move with the flight condition: those that are a force or moment
per unit state scale with the dynamic pressure (V^2: M_alpha, M_u, M_de, X_alpha, X_de), those that are also
divided by V (the alpha row: Z_alpha/V, Z_de/V) or carry a rate (M_q, X_u) scale with V, and the kinematic and
gravity terms (alpha' = q + ..., theta' = q, the -g theta in u') stay. The trim moves too: alpha at 1 g goes as
1/V^2, theta with it (level flight), and the elevator trim with alpha. A model a user would identify at each leg
of a slow-down, not a flight-mechanics model.

``documented_envelope()``: the small envelope of ``docs/explanation/envelope.md`` (two points of a short-period
model), as the page shows it: a design of it takes a few seconds, for tests of the envelope's plumbing (a cluster, a
command's per-point output) that need a real design but not the aircraft's size.

``no_common_p_pair()``: two discrete plants whose loops are each stable while switching between them diverges: the
state matrices ``A1 = [[0.6, 1.5], [0, 0.6]]`` and ``A2 = A1'`` have spectral radius 0.6 each, but ``A1 A2`` has
2.93 (> 1), so no common quadratic Lyapunov function exists; the input does not reach the state (``B0 = B1 = 0``),
so no controller can change it: the loop's plant block is ``A_i`` whatever the gains.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np

from monitor.model.closed_loop import Gains
from tests.aircraft_files import AIRCRAFT_PLANT, OP

# exponents of V / V0 for each entry of A_c (rows and columns: alpha, q, theta, airspeed) and of B_c
_A_POWERS = np.array([[1, 0, -1, 0], [2, 1, 0, 1], [0, 0, 0, 0], [2, 0, 0, 1]])
_B_POWERS = np.array([[1], [2], [0], [2]])


def scaled_model(A_c: np.ndarray, B_c: np.ndarray, V: float, V_ref: float) -> tuple[np.ndarray, np.ndarray]:
    """``(A_c, B_c)`` of a longitudinal model (alpha, q, theta, airspeed; elevator) moved from V_ref to V."""
    r = V / V_ref
    return np.asarray(A_c) * r**_A_POWERS, np.asarray(B_c) * r**_B_POWERS


def trim_at(V: float, ref: dict[str, float] = OP) -> dict[str, float]:
    """The operating point at V from the one at ``ref``: alpha ~ 1/V^2 at 1 g, theta = alpha (level flight), the
    elevator trim with alpha."""
    alpha = ref["alpha"] * (ref["airspeed"] / V) ** 2
    return {
        "alpha": alpha,
        "q": 0.0,
        "theta": alpha,
        "airspeed": float(V),
        "elevator": ref["elevator"] * alpha / ref["alpha"],
    }


def _rows(a: np.ndarray) -> str:
    return repr(np.asarray(a, dtype=float).tolist())


def plant_text(
    V: float, *, base: str = AIRCRAFT_PLANT, h: float | None = None, name: str | None = None, op: bool = True
) -> str:
    """A single-point plant file of the aircraft ``base`` (a plant file with a [signals] operating point) moved to
    airspeed V: what ``identify`` would write from a leg flown at V. Its tables after [signals] come along."""
    raw = tomllib.loads(base)
    ref = raw["signals"]["operating_point"]
    A_c, B_c = scaled_model(np.array(raw["A_c"]), np.array(raw["B_c"]), V, ref["airspeed"])
    trim = trim_at(V, ref)
    signals = base[re.search(r"^\[signals\]", base, flags=re.M).start() :]  # type: ignore[union-attr]
    point = "{ " + ", ".join(f"{k} = {v!r}" for k, v in trim.items()) + " }"
    signals = re.sub(r"operating_point = \{[^}]*\}", f"operating_point = {point}" if op else "", signals)
    return (
        f'form = "continuous"\nname = "{name or f"c172p-{V:g}"}"\nh = {h or raw["h"]}\n'
        f"tau_min = {raw['tau_min']}\ntau_max = {raw['tau_max']}\n"
        f"A_c = {_rows(A_c)}\nB_c = {_rows(B_c)}\nD_cf = {_rows(B_c)}\nD_cd = {_rows(A_c[:, [0]])}\n"
        f"C = {_rows(np.eye(4))}\n\n[actuator]\nlimit = 25.0\n\n{signals}"
    )


def documented_envelope() -> str:
    """The envelope plant file that ``docs/explanation/envelope.md`` shows (its one TOML block with an envelope)."""
    page = (Path(__file__).resolve().parents[1] / "docs" / "explanation" / "envelope.md").read_text()
    (text,) = [b for b in re.findall(r"```toml\n(.*?)```", page, flags=re.S) if 'form = "envelope"' in b]
    return text


A1 = np.array([[0.6, 1.5], [0.0, 0.6]])
A2 = A1.T.copy()

_PAIR_SIGNALS = """
[signals]
instant = "AOA_SSA"
outputs = ["alpha", "q"]
actuator = ["elevator"]
[signals.measured]
alpha = {{ field = "AOA_SSA.AOA", unit = "deg" }}
q = {{ field = "ATTITUDE.pitchspeed", scale = 57.29577951308232, unit = "deg/s" }}
airspeed = {{ field = "VFR_HUD.airspeed", unit = "m/s" }}
elevator = {{ field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }}
"""


def pair_plant_table(A: np.ndarray) -> str:
    """The body of a ``[point.plant]`` of :func:`no_common_p_pair` (discrete form, no delay, B = 0)."""
    signals = _PAIR_SIGNALS.replace("{{", "{").replace("}}", "}").replace("[signals", "[point.plant.signals")
    return (
        f'form = "discrete"\nh = 0.1\ntau_min = 0.0\ntau_max = 0.0\nA = {_rows(A)}\nB0 = [[0.0], [0.0]]\n'
        f"B1 = [[0.0], [0.0]]\nC = {_rows(np.eye(2))}\nDf = [[1.0], [0.0]]\nDd = [[0.0], [1.0]]\n{signals}"
    )


def no_common_p_pair() -> str:
    """An envelope of two points scheduled by airspeed whose loops have no common Lyapunov matrix."""
    return (
        'form = "envelope"\nname = "no-common-p"\nschedule = ["airspeed"]\n\n'
        f'[[point]]\nname = "a"\nat = {{ airspeed = 30.0 }}\n[point.plant]\n{pair_plant_table(A1)}\n'
        f'[[point]]\nname = "b"\nat = {{ airspeed = 40.0 }}\n[point.plant]\n{pair_plant_table(A2)}'
    )


# A short-period model (alpha, q; elevator) with airspeed a measured signal that is not an output; the gains are a
# certified design of it copied here (a design takes a second).
A_C = np.array([[-2.36, 0.956], [-20.5, -4.38]])
B_C = np.array([[-0.155], [-13.8]])
SP_GAINS = Gains(
    L=np.array([[0.5268014, 0.08822641], [-0.28176835, 1.76230559]]),
    M=np.array([[-0.36030215, -1.62308954]]),
    K1=np.array([[-0.24775598, 0.09584355]]),
    K2=np.array([[0.76695437]]),
    K3=np.array([[-0.23304563]]),
)


def short_period(alpha: float, q: float, elevator: float) -> str:
    return f"""form = "continuous"
h = 0.05
tau_min = 0.0
tau_max = 0.023
A_c = {A_C.tolist()}
B_c = {B_C.tolist()}
D_cf = {B_C.tolist()}
D_cd = {A_C[:, [0]].tolist()}
C = [[1.0, 0.0], [0.0, 1.0]]
[actuator]
limit = 25.0
[signals]
instant = "AOA_SSA"
outputs = ["alpha", "q"]
actuator = ["elevator"]
operating_point = {{ alpha = {float(alpha)!r}, q = {float(q)!r}, elevator = {float(elevator)!r} }}
[signals.measured]
alpha = {{ field = "AOA_SSA.AOA", unit = "deg" }}
q = {{ field = "ATTITUDE.pitchspeed", scale = 57.29577951308232, unit = "deg/s" }}
elevator = {{ field = "ACTUATOR_OUTPUT_STATUS.actuator[0]", unit = "deg" }}
airspeed = {{ field = "VFR_HUD.airspeed", unit = "m/s" }}
"""
