"""Fault and delay SPEC parsing (monitor/wire/specs.py): the grammar of the contract, errors, statistics."""

from __future__ import annotations

import numpy as np
import pytest

from monitor.errors import UserError
from monitor.wire.specs import parse_delay_spec, parse_fault_spec


def test_bias_step_and_intermittent_end_is_exclusive():
    s = parse_fault_spec("bias:2@20")
    assert [s.f(k) for k in (0, 19, 20, 500)] == [0.0, 0.0, 2.0, 2.0]
    s = parse_fault_spec("bias:2@20-60")
    assert [s.f(k) for k in (19, 20, 59, 60)] == [0.0, 2.0, 2.0, 0.0]
    assert s.onset == 20 and s.additive_only and s.active(30) and not s.active(60)


def test_ramp_starts_at_zero_and_terms_add_up():
    s = parse_fault_spec("ramp:0.1@20+bias:-1@25")
    assert s.f(20) == 0.0
    assert s.f(30) == pytest.approx(1.0 - 1.0)
    assert s.f_vector(30, q=2) == [pytest.approx(0.0), 0.0]


def test_loe_and_stuck_act_on_the_deflection():
    s = parse_fault_spec("loe:0.5@20+loe:0.5@40+stuck@30-35+stuck:5@32")
    assert s.f(50) == 0.0 and not s.additive_only
    assert [s.effectiveness(k) for k in (19, 20, 40)] == [1.0, 0.5, 0.25]
    assert s.stuck(29) is None and s.stuck(30).value is None  # earliest start wins
    assert s.stuck(36).value == 5.0
    assert str(s) == "loe:0.5@20+loe:0.5@40+stuck@30-35+stuck:5@32"


@pytest.mark.parametrize("text", [None, "", "none", " NONE "])
def test_no_fault(text):
    s = parse_fault_spec(text)
    assert s.events == () and s.onset is None and s.f(10) == 0.0 and s.effectiveness(10) == 1.0


@pytest.mark.parametrize(
    "text",
    ["bias@2", "bias:2", "foo:1@2", "loe:1.5@3", "bias:1@5-3", "bias:2@20+", "bias:nan@3", "bias:2@-1", "stuck@"],
)
def test_bad_fault_spec_is_one_line_naming_it(text):
    with pytest.raises(UserError) as info:
        parse_fault_spec(text)
    msg = str(info.value)
    assert f"'{text}'" in msg and "\n" not in msg


@pytest.mark.parametrize(
    "text",
    [
        "const",
        "const:-1",
        "uniform:1",
        "uniform:2:1",
        "normal:0.2:-1",
        "normal:x:1",
        "gamma:1:2",
        "trace:",
        "trace:/definitely/missing.txt",
        "const:inf",
    ],
)
def test_bad_delay_spec_is_one_line_naming_it(text):
    with pytest.raises(UserError) as info:
        parse_delay_spec(text)
    assert f"'{text}'" in str(info.value) and "\n" not in str(info.value)


def test_delay_draws_are_pure_functions_of_seed_and_k():
    a, b = parse_delay_spec("uniform:0:0.46", seed=4), parse_delay_spec("uniform:0:0.46", seed=4)
    assert [a.tau(k) for k in range(50)] == [b.tau(k) for k in reversed(range(50))][::-1]
    assert a.tau(3) != parse_delay_spec("uniform:0:0.46", seed=5).tau(3)


def test_delay_statistics_match_the_requested_distribution():
    n = 20000
    u = np.array([parse_delay_spec("uniform:0.1:0.4", seed=1).tau(k) for k in range(n)])
    assert u.min() >= 0.1 and u.max() <= 0.4
    assert u.mean() == pytest.approx(0.25, abs=0.005) and u.std() == pytest.approx(0.3 / np.sqrt(12), abs=0.004)
    g = np.array([parse_delay_spec("normal:0.2:0.05", seed=2).tau(k) for k in range(n)])
    assert g.mean() == pytest.approx(0.2, abs=0.002) and g.std() == pytest.approx(0.05, abs=0.002)
    clipped = np.array([parse_delay_spec("normal:0:0.1", seed=2).tau(k) for k in range(2000)])
    assert clipped.min() == 0.0 and np.mean(clipped == 0.0) == pytest.approx(0.5, abs=0.05)
    assert parse_delay_spec("const:0.2").tau(99) == 0.2


def test_trace_is_read_relative_and_cycled(tmp_path):
    (tmp_path / "d.txt").write_text("0.1\n# comment\n0.2\n\n0.3\n")
    d = parse_delay_spec("trace:d.txt", base_dir=tmp_path)
    assert [d.tau(k) for k in range(4)] == [0.1, 0.2, 0.3, 0.1] and d.mean == pytest.approx(0.2)
    (tmp_path / "bad.txt").write_text("0.1\n-2\n")
    with pytest.raises(UserError, match="bad.txt:2"):
        parse_delay_spec(f"trace:{tmp_path / 'bad.txt'}")
