"""One vehicle's loop state as JSON and back: what a monitor group member copies from the owner to be warm again.

Why these fields and no others: the next command is ``U [z; y]`` and the next state ``O [z; y; u]``, so the
estimator state ``z = [x_hat; f_hat; u(k-1)]`` at ``k_last`` (with the low-passed ``f_reported``) decides every
later estimate and command; the last command and the window of applied judgements decide the ``applied`` flag of
the next step (the held-deflection correction); the alarm's state decides its next event; an envelope model's trim
and point are the origin of the deviations. Counters, the observed delay and the route stay the member's own.

Exact: JSON writes a float as its shortest ``repr``, which reads back to the same double, so a copied state
steps to the same bits as the original on the same samples.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from monitor.service.vehicles import Vehicle

__all__ = ["export_state", "import_state"]


def export_state(vehicle: Vehicle) -> dict[str, Any] | None:
    """The vehicle's loop state (None before its first processed sample: nothing to copy)."""
    s = vehicle.state
    if s.k_last is None:
        return None
    trim = vehicle.trim
    return {
        "k": s.k_last,
        "z": s.z.tolist(),
        "f_reported": s.f_reported,
        "last_command": vehicle.last_command,
        "last_command_k": vehicle.last_command_k,
        "last_compensation": vehicle.last_compensation,
        "applied": list(vehicle.applied),
        "commands_effective": vehicle.commands_effective,
        "alarm": [vehicle.alarm.raised, vehicle.alarm._count],
        "trim": None if trim is None else [trim[0].tolist(), list(trim[1]), list(trim[2])],
        "input_trim": vehicle.input_trim,
        "point": vehicle.point,
    }


def import_state(vehicle: Vehicle, data: dict[str, Any]) -> bool:
    """Take over ``data`` (``export_state`` of the same vehicle in another member) if it is at this vehicle's own
    last sample; False (nothing changed) when the two are at different samples or the models differ in size."""
    s = vehicle.state
    if s.k_last is None or data.get("k") != s.k_last or len(data["z"]) != s.z.size:
        return False
    s.z = np.array(data["z"], dtype=float)
    s.f_reported = None if data["f_reported"] is None else [float(v) for v in data["f_reported"]]
    vehicle.last_command = data["last_command"]
    vehicle.last_command_k = data["last_command_k"]
    vehicle.last_compensation = data["last_compensation"]
    vehicle.applied.clear()
    vehicle.applied.extend(bool(a) for a in data["applied"])
    vehicle.commands_effective = bool(data["commands_effective"])
    vehicle.alarm.raised, vehicle.alarm._count = bool(data["alarm"][0]), int(data["alarm"][1])
    trim = data["trim"]
    vehicle.trim = None if trim is None else (np.array(trim[0], dtype=float), tuple(trim[1]), tuple(trim[2]))
    vehicle.input_trim = data["input_trim"]
    vehicle.point = data["point"]
    return True
