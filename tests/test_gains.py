"""Gains files: written compactly (as in CONTRACT.md) and read back exactly."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from monitor.design.result import DesignResult
from monitor.errors import UserError
from monitor.gains import read_gains, write_gains
from monitor.model.closed_loop import Gains
from monitor.model.plant import load_plant


def test_round_trip_is_exact_and_matrices_are_one_line(tmp_path):
    plant = load_plant("paper")
    rng = np.random.default_rng(1)
    gains = Gains(
        L=rng.normal(size=(2, 1)),
        M=rng.normal(size=(1, 1)),
        K1=rng.normal(size=(1, 1)),
        K2=rng.normal(size=(1, 1)),
        K3=np.array([[1e-300]]),
    )
    result = DesignResult(
        method="certified",
        gains=gains,
        gamma_e=1.8,
        gamma_z=1.6,
        build_seconds=0.1,
        solve_seconds=0.2,
        total_seconds=0.3,
        certificate={"P": np.eye(6), "vertices": rng.normal(size=(4, 2))},
        notes=['a "quoted" note\nwith a newline and ünïcode \\ backslash'],
    )
    path = tmp_path / "g.toml"
    write_gains(path, result, plant)
    text = path.read_text()
    assert f"L = [[{float(gains.L[0, 0])!r}], [{float(gains.L[1, 0])!r}]]" in text
    back = read_gains(path)
    for name in ("L", "M", "K1", "K2", "K3"):
        np.testing.assert_array_equal(getattr(back.gains, name), getattr(gains, name))
    np.testing.assert_array_equal(back.certificate["vertices"], result.certificate["vertices"])
    assert tomllib.loads(text)["notes"]["lines"] == result.notes
    assert back.meta["plant_hash"] == plant.digest and back.method == "certified"


def test_unknown_keys_are_refused(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text(
        "[gains]\nL = [[1.0], [2.0]]\nM = [[1.0]]\nK1 = [[0.0]]\nK2 = [[0.0]]\nK3 = [[0.0]]\nK4 = [[0.0]]\n"
    )
    with pytest.raises(UserError, match="gains.K4"):
        read_gains(path)


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_a_gains_file_follows_the_umask(tmp_path, umask, mode):
    import os

    plant = load_plant("paper")
    result = DesignResult(
        method="hand",
        gains=Gains.zero(plant),
        gamma_e=0.0,
        gamma_z=0.0,
        build_seconds=0.0,
        solve_seconds=0.0,
        total_seconds=0.0,
    )
    old = os.umask(umask)
    try:
        write_gains(tmp_path / "g.toml", result, plant)
    finally:
        os.umask(old)
    assert (tmp_path / "g.toml").stat().st_mode & 0o777 == mode
