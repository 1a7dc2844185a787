"""Alarm hysteresis and persistence (monitor/service/alarm.py)."""

from __future__ import annotations

import pytest

from monitor.service.alarm import Alarm, AlarmConfig


def run(alarm: Alarm, values: list[float]) -> list[str | None]:
    return [alarm.update(v) for v in values]


def test_raises_after_persistence_and_clears_with_hysteresis() -> None:
    alarm = Alarm(AlarmConfig(threshold=1.0, clear=0.5, samples=2))
    events = run(alarm, [0.2, 1.2, 0.3, 1.1, 1.3, 0.8, 0.5, 0.4, 0.6, 0.45, 0.1])
    assert events == [None, None, None, None, "raised", None, None, None, None, None, "cleared"]
    assert not alarm.raised


def test_single_sample_config_and_vector_magnitude_is_callers() -> None:
    alarm = Alarm(AlarmConfig(threshold=2.0, clear=2.0, samples=1))
    assert run(alarm, [2.0, 2.0, 1.9]) == ["raised", None, "cleared"]


@pytest.mark.parametrize(
    "kwargs", [dict(threshold=0.0), dict(threshold=1.0, clear=2.0), dict(samples=0), dict(threshold=1.0, clear=-0.1)]
)
def test_rejects_inconsistent_config(kwargs) -> None:
    with pytest.raises(ValueError):
        AlarmConfig(**kwargs)
