"""The wind SPEC (monitor/wire/specs.py): the paper's oscillator exactly, seeded turbulence statistically."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.wire.specs import PAPER_ROTATION, parse_wind_spec


def test_paper_oscillator_is_the_published_recursion():
    d = parse_wind_spec("paper", h=1.0).series(50)
    s = np.array([0.01, 0.0])
    for k in range(50):
        assert d[k] == pytest.approx(0.1 * s[0], abs=1e-15)
        s = PAPER_ROTATION @ s


def test_turbulence_is_seeded_with_the_requested_std_and_correlation():
    a = parse_wind_spec("turbulence:0.3:4", h=1.0, seed=9).series(40000)
    b = parse_wind_spec("turbulence:0.3:4", h=1.0, seed=9).series(100)
    assert np.array_equal(a[:100], b)
    assert a.std() == pytest.approx(0.3, rel=0.06)
    lag1 = np.corrcoef(a[:-1], a[1:])[0, 1]
    assert lag1 == pytest.approx(np.exp(-1 / 4), abs=0.02)
    assert np.all(parse_wind_spec("none", h=1.0).series(10) == 0.0)
    both = parse_wind_spec("paper+turbulence:0.3:4", h=1.0, seed=9).series(100)
    assert np.allclose(both - b, parse_wind_spec("paper", h=1.0).series(100))


@pytest.mark.parametrize("text", ["gust", "turbulence", "turbulence:-1", "turbulence:1:2:3", "paper:2"])
def test_bad_wind_spec(text):
    with pytest.raises(UserError, match="bad wind SPEC"):
        parse_wind_spec(text, h=1.0)
