"""The per-vehicle table: models, refusal, duplicates/stale, timeout, restart (monitor/service/vehicles.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from monitor.errors import UserError
from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_fleet, load_model
from monitor.service.vehicles import VehicleTable
from tests.vehicle_table import feed


def test_plant_hash_mismatch_is_refused_unless_forced(gains_path: Path) -> None:
    with pytest.raises(UserError, match="--force"):
        load_model("paper", gains_path)
    assert load_model("paper", gains_path, force=True).plant.name == "paper"


def test_duplicates_and_stale_are_counted_and_not_processed(gains_path: Path) -> None:
    table = VehicleTable(Fleet(load_model("paper-continuous", gains_path)), AlarmConfig())
    ks = [0, 1, 1, 3, 2, 3, 4, 0]
    done = [p.result.k for k in ks if (p := feed(table, 1, k, "A", 0.0)) is not None]
    assert done == [0, 1, 3, 4]
    c, a = table.counters, table.assembly_totals()
    assert (c.processed, a["duplicates"], a["stale"], c.skipped) == (4, 2, 2, 1)


def test_unknown_vehicle_refused_with_one_log_line(gains_path: Path, caplog) -> None:
    table = VehicleTable(Fleet(None, {1: load_model("paper-continuous", gains_path)}), AlarmConfig())
    with caplog.at_level("WARNING"):
        for k in range(3):
            assert feed(table, 9, k, "B", 0.0) is None
    assert table.counters.refused == 3
    assert sum("refusing vehicle sysid 9" in r.message for r in caplog.records) == 1
    assert feed(table, 1, 0, "A", 0.0) is not None


def test_vehicles_have_separate_state_and_expire(gains_path: Path) -> None:
    table = VehicleTable(Fleet(load_model("paper-continuous", gains_path)), AlarmConfig(), timeout=5.0)
    for k in range(5):
        a = feed(table, 1, k, "A", float(k), alpha=1.0)
        b = feed(table, 2, k, "B", float(k), alpha=0.0)
    assert a.result.f_hat[0] != 0.0 and b.result.f_hat[0] == 0.0
    assert table.expire(8.0) == []
    assert sorted(table.expire(10.0)) == [1, 2]
    assert feed(table, 1, 0, "A", 11.0).result.k == 0  # a fresh estimator after the timeout


def test_restart_from_a_new_peer_starts_fresh_but_a_replay_does_not(gains_path: Path) -> None:
    table = VehicleTable(
        Fleet(load_model("paper-continuous", gains_path)), AlarmConfig(), timeout=30.0, restart_silence=1.0
    )
    for k in range(10):
        feed(table, 1, k, "A", k * 0.01)
    assert feed(table, 1, 2, "X", 0.095) is None  # replay while A is live: stale
    p = feed(table, 1, 0, "B", 2.0)  # A silent for ~2 s, B starts over
    assert p is not None and p.result.k == 0 and table.counters.restarts == 1


def test_fleet_file(tmp_path: Path, gains_path: Path) -> None:
    fleet_toml = tmp_path / "fleet.toml"
    fleet_toml.write_text(
        f'[vehicle.3]\nplant = "paper-continuous"\ngains = "{gains_path}"\n'
        f'[vehicle.4]\nplant = "paper-continuous"\ngains = "{gains_path}"\n'
    )
    fleet = load_fleet(fleet_toml, None)
    assert fleet.model_for(3) is fleet.model_for(4) and fleet.model_for(5) is None
    fleet_toml.write_text('[vehicle.x]\nplant = "paper"\n')
    with pytest.raises(UserError, match="system id"):
        load_fleet(fleet_toml, None)
