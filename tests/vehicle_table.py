"""Feeding a ``VehicleTable`` by hand, shared by the table's test modules (``test_service_vehicles``,
``test_service_restart``): one AOA_SSA is a whole sample for the default signal map, so a test drives
the table one sample at a time without a link or a socket.
"""

from __future__ import annotations

from monitor.link.dialect import layout_by_name
from monitor.service.vehicles import VehicleTable

_AOA = layout_by_name("AOA_SSA")


def feed(table: VehicleTable, sysid: int, k: int, route: str, now: float, alpha: float = 0.1):
    """One AOA_SSA (all the default map's y needs) for sample k; the processed result or None."""
    ready = table.message(sysid, "AOA_SSA", _AOA.decode(_AOA.unpacker.pack(k * 1_000_000, alpha, 0.0)), route, now)
    done = [table.process(v, s, 0.0) for v, s in ready]
    return done[-1] if done else None
