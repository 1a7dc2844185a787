"""The estimate payload the loop formats itself (``estimate_json``) is the contract's, as ``json.dumps`` writes it."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from monitor.service.publisher import estimate_json, estimate_payload

ITEMS = [
    (1, 5, 0.1, np.array([0.25]), np.array([1e-7, -3.5]), np.array([0.0, 2.0]), [0.5], None, False, None, True, None),
    (
        200,
        123456,
        2469.12,
        np.array([math.nan, 1.0]),
        np.array([math.inf, -math.inf]),
        np.array([1.5]),
        [np.float64(-0.75), 3],
        0.0123,
        True,
        False,
        False,
        ("trim 40 m/s", False),
    ),
    (3, 0, 0.0, [0.1, 0.2], [], np.array([], dtype=float), [], 1e-300, True, True, False, None),
]


@pytest.mark.parametrize("member", [None, "ground-a", 'odd "name"'])
@pytest.mark.parametrize("item", ITEMS)
def test_estimate_json_is_json_dumps_of_the_payload(item, member) -> None:
    text = estimate_json(item, "deg", member)
    expected = json.dumps(estimate_payload(item, "deg", member), allow_nan=False)
    assert json.loads(text) == json.loads(expected)
    assert list(json.loads(text)) == list(json.loads(expected))  # the same keys in the same order
    assert json.loads(text).get("member") == member  # a group member names itself; a lone monitor adds no key


def test_a_non_finite_time_is_refused_as_json_dumps_refuses_it() -> None:
    item = (1, 0, math.nan, [0.0], [0.0], [0.0], [0.0], None, False, None, True)
    with pytest.raises(ValueError):
        json.dumps(estimate_payload(item, "deg"), allow_nan=False)
    with pytest.raises(ValueError):
        estimate_json(item, "deg")
