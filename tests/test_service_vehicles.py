"""The per-vehicle table: models, refusal, duplicates/stale, timeout, restart (monitor/service/vehicles.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monitor.model.closed_loop import Gains
from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.gains import write_gains
from monitor.model.plant import load_plant
from monitor.service.alarm import AlarmConfig
from monitor.link.dialect import layout_by_name
from monitor.service.fleet_file import Fleet, load_fleet, load_model
from monitor.service.vehicles import VehicleTable


def _gains_file(path: Path, plant_name: str = "paper-continuous") -> Path:
    """A hand-made stabilising-enough gains file (the table's logic does not depend on the design)."""
    plant = load_plant(plant_name)
    gains = Gains(L=np.array([[1.8], [1.6]]), M=np.array([[0.9]]), K1=np.array([[-0.26]]), K2=np.array([[0.1]]),
                  K3=np.array([[-1.0]]))
    result = DesignResult(method="test", gains=gains, gamma_e=1.0, gamma_z=1.0,
                          build_seconds=0.0, solve_seconds=0.0, total_seconds=0.0)
    write_gains(path, result, plant)
    return path


@pytest.fixture(scope="module")
def gains_path(tmp_path_factory) -> Path:
    return _gains_file(tmp_path_factory.mktemp("g") / "gains.toml")


_AOA = layout_by_name("AOA_SSA")


def feed(table: VehicleTable, sysid: int, k: int, route: str, now: float, alpha: float = 0.1):
    """One AOA_SSA (all the default map's y needs) for sample k; the processed result or None."""
    ready = table.message(sysid, "AOA_SSA", _AOA.decode(_AOA.unpacker.pack(k * 1_000_000, alpha, 0.0)), route, now)
    done = [table.process(v, s, 0.0) for v, s in ready]
    return done[-1] if done else None


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
    table = VehicleTable(Fleet(load_model("paper-continuous", gains_path)), AlarmConfig(), timeout=30.0,
                         restart_silence=1.0)
    for k in range(10):
        feed(table, 1, k, "A", k * 0.01)
    assert feed(table, 1, 2, "X", 0.095) is None  # replay while A is live: stale
    p = feed(table, 1, 0, "B", 2.0)  # A silent for ~2 s, B starts over
    assert p is not None and p.result.k == 0 and table.counters.restarts == 1


def test_fleet_file(tmp_path: Path, gains_path: Path) -> None:
    fleet_toml = tmp_path / "fleet.toml"
    fleet_toml.write_text(f'[vehicle.3]\nplant = "paper-continuous"\ngains = "{gains_path}"\n'
                          f'[vehicle.4]\nplant = "paper-continuous"\ngains = "{gains_path}"\n')
    fleet = load_fleet(fleet_toml, None)
    assert fleet.model_for(3) is fleet.model_for(4) and fleet.model_for(5) is None
    fleet_toml.write_text('[vehicle.x]\nplant = "paper"\n')
    with pytest.raises(UserError, match="system id"):
        load_fleet(fleet_toml, None)
