"""A vehicle restarted under the same sysid, whatever message it sends first (monitor/service/vehicles.py).

Why these cases: a restarted vehicle is heard from a new source port after silence, and its first message
is as often a HEARTBEAT (no time field) or an ATTITUDE as the instant message. The table used to rebind the
route on such a message without a restart, and then counted every sample of the new run as stale.
"""

from __future__ import annotations

from pathlib import Path

from monitor.link.dialect import layout_by_name
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.vehicles import VehicleTable
from tests.vehicle_table import feed

_ATTITUDE = layout_by_name("ATTITUDE")
RUN = 60  # samples per run; h = 1 s, so k is the vehicle's time in seconds
SILENCE = 2.0  # > restart_silence (1 s)


def _table(gains: Path) -> VehicleTable:
    return VehicleTable(Fleet(load_model("paper-continuous", gains)), AlarmConfig(), timeout=30.0, restart_silence=1.0)


def _heartbeat(table: VehicleTable, route: str, now: float) -> list:
    """A HEARTBEAT as the table sees it: no field the signal map knows, so no k."""
    return table.message(1, "HEARTBEAT", (), route, now)


def _attitude(table: VehicleTable, k: int, route: str, now: float) -> list:
    """ATTITUDE for sample k: matched by ``time_boot_ms``, not the instant message."""
    values = _ATTITUDE.decode(_ATTITUDE.unpacker.pack(k * 1000, 0.0, 0.0, 0.0, 0.0, 0.01, 0.0))
    return table.message(1, "ATTITUDE", values, route, now)


def _first_run(table: VehicleTable) -> float:
    """Samples 0..RUN-1 from route A, 10 ms apart; returns when the last one came."""
    for k in range(RUN):
        assert feed(table, 1, k, "A", k * 0.01) is not None
    return (RUN - 1) * 0.01


def test_restart_whose_first_messages_are_heartbeat_then_attitude_is_a_restart(gains_path: Path) -> None:
    table = _table(gains_path)
    t = _first_run(table) + SILENCE
    assert _heartbeat(table, "B", t) == []  # the route changes, but nothing says "restart" yet
    assert table.counters.restarts == 0
    assert _attitude(table, 0, "B", t + 0.001) == []  # k 0 < 59 from the new route: the restart
    assert table.counters.restarts == 1
    done = [feed(table, 1, k, "B", t + 0.01 * (k + 1)) for k in range(RUN)]
    assert all(p is not None for p in done) and [p.result.k for p in done] == list(range(RUN))
    assert {p.vehicle.run for p in done} == {1}  # a new run: the recording keeps both
    assert table.counters.processed == 2 * RUN and table.assembly_totals()["stale"] == 0
    assert table.vehicles[1].route == "B"


def test_restart_whose_first_message_is_attitude_is_a_restart(gains_path: Path) -> None:
    """What ``sim-vehicle`` sends first in every datagram."""
    table = _table(gains_path)
    t = _first_run(table) + SILENCE
    _attitude(table, 0, "B", t)
    p = feed(table, 1, 0, "B", t + 0.001)
    assert p is not None and p.result.k == 0 and p.vehicle.run == 1 and table.counters.restarts == 1


def test_a_new_route_that_continues_the_clock_is_no_restart_and_later_stale_is_stale(gains_path: Path) -> None:
    """A route change without a restart (the vehicle moved behind a router): its k goes on, nothing restarts;
    once it has given a sample, an old k from it is stale as from any bound route."""
    table = _table(gains_path)
    t = _first_run(table) + SILENCE
    _heartbeat(table, "B", t)
    assert feed(table, 1, RUN, "B", t + 0.01) is not None
    assert feed(table, 1, RUN - 5, "B", t + 0.02) is None
    assert table.counters.restarts == 0 and table.assembly_totals()["stale"] == 1


def test_a_replay_from_another_address_while_live_is_still_refused(gains_path: Path) -> None:
    table = _table(gains_path)
    t = _first_run(table)
    assert _heartbeat(table, "X", t + 0.1) == []
    assert _attitude(table, 3, "X", t + 0.2) == []
    assert feed(table, 1, 2, "X", t + 0.3) is None
    assert table.counters.foreign_source == 3 and table.counters.restarts == 0
    p = feed(table, 1, RUN, "A", t + 0.4)  # the bound route goes on undisturbed
    assert p is not None and p.vehicle.route == "A" and p.vehicle.run == 0


def test_a_heartbeat_from_another_address_while_live_does_not_open_a_takeover(gains_path: Path) -> None:
    """Refused messages change nothing: a later backwards k from the bound route is stale, not a restart."""
    table = _table(gains_path)
    t = _first_run(table)
    _heartbeat(table, "X", t + 0.1)
    assert feed(table, 1, 5, "A", t + 0.2) is None
    assert table.counters.restarts == 0 and table.assembly_totals()["stale"] == 1
