"""Sample assembly: parts of one instant in any order, duplicates and late parts counted, bounded waits."""

from __future__ import annotations

import itertools

from monitor.link.assembly import SampleAssembler
from monitor.link.dialect import layout_by_name
from monitor.link.signals import DEFAULT_SIGNALS_TOML, default_signal_map

H = 0.02
ATT, AOA, ACT = (layout_by_name(n) for n in ("ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS"))


def parts(k: int, alpha: float = 1.0, q_rad: float = 0.01, elevator: float = -2.0, t0_us: int = 0) -> dict:
    t_us = t0_us + k * 20_000
    return {
        "ATTITUDE": ATT.decode(ATT.unpacker.pack(((t_us // 1000) & 0xFFFFFFFF), 0, 0, 0, 0, q_rad, 0)),
        "AOA_SSA": AOA.decode(AOA.unpacker.pack(t_us, alpha, 0.0)),
        "ACTUATOR_OUTPUT_STATUS": ACT.decode(ACT.unpacker.pack(t_us, 1, elevator, *[0.0] * 31)),
    }


def test_every_order_gives_the_same_sample_once_all_parts_are_in() -> None:
    for order in itertools.permutations(["ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS"]):
        asm = SampleAssembler(default_signal_map(), H)
        asm.add("ACTUATOR_OUTPUT_STATUS", parts(0)["ACTUATOR_OUTPUT_STATUS"], "r", 0.0)  # learn: it reports
        asm.add("AOA_SSA", parts(0)["AOA_SSA"], "r", 0.0)
        got = []
        for name in order:
            got += asm.add(name, parts(1, alpha=3.0, elevator=-4.0)[name], "r", 0.1)
        assert [s.k for s in got] == [1], order
        assert got[0].values["alpha"] == 3.0 and got[0].values["elevator"] == -4.0
        if order[-1] == "ATTITUDE":  # q is not what y needs: the sample does not wait for it
            assert "q" not in got[0].values
        else:
            assert abs(got[0].values["q"] - 0.01 * 57.29577951308232) < 1e-6


def test_duplicates_stale_and_late_parts_are_counted_not_processed() -> None:
    asm = SampleAssembler(default_signal_map(), H)
    assert [s.k for s in asm.add("AOA_SSA", parts(5)["AOA_SSA"], "r", 0.0)] == [5]  # y needs only AOA_SSA
    assert asm.add("AOA_SSA", parts(5)["AOA_SSA"], "r", 0.0) == []
    assert asm.add("AOA_SSA", parts(3)["AOA_SSA"], "r", 0.0) == []
    assert asm.add("ATTITUDE", parts(5)["ATTITUDE"], "r", 0.0) == []
    c = asm.counters
    assert (c.samples, c.duplicates, c.stale, c.late_parts) == (1, 1, 1, 1)


def test_a_vehicle_that_reports_its_actuator_is_waited_for_boundedly() -> None:
    asm = SampleAssembler(default_signal_map(), H, wait_s=0.05)
    p0 = parts(0)
    asm.add("ACTUATOR_OUTPUT_STATUS", p0["ACTUATOR_OUTPUT_STATUS"], "r", 0.0)
    assert [s.k for s in asm.add("AOA_SSA", p0["AOA_SSA"], "r", 0.0)] == [0]
    assert asm.add("AOA_SSA", parts(1)["AOA_SSA"], "r", 1.0) == []  # waits for its report
    assert asm.poll(1.01) == []
    late = asm.poll(1.06)
    assert [s.k for s in late] == [1] and "elevator" not in late[0].values and asm.counters.waited_out == 1
    for k in (2, 3, 4):  # the reports stopped: after three timeouts it is no longer waited for
        asm.add("AOA_SSA", parts(k)["AOA_SSA"], "r", float(k))
        asm.poll(k + 0.1)
    assert [s.k for s in asm.add("AOA_SSA", parts(5)["AOA_SSA"], "r", 5.0)] == [5]


def test_observe_only_needs_the_report_and_incomplete_instants_are_dropped() -> None:
    asm = SampleAssembler(default_signal_map(), H, observe=True)
    asm.add("AOA_SSA", parts(0)["AOA_SSA"], "r", 0.0)  # never completed: its report is lost
    p1 = parts(1)
    asm.add("AOA_SSA", p1["AOA_SSA"], "r", 0.0)
    assert [s.k for s in asm.add("ACTUATOR_OUTPUT_STATUS", p1["ACTUATOR_OUTPUT_STATUS"], "r", 0.0)] == [1]
    assert asm.counters.incomplete == 1


def test_time_boot_ms_is_matched_across_its_32_bit_wrap() -> None:
    t0 = (1 << 32) * 1000 - 40_000  # two samples before time_boot_ms wraps
    asm = SampleAssembler(default_signal_map(), H, wait_s=1.0)
    for k in range(4):
        p = parts(k, q_rad=0.1 * k, t0_us=t0)
        asm.add("ATTITUDE", p["ATTITUDE"], "r", 0.0)
        asm.add("ACTUATOR_OUTPUT_STATUS", p["ACTUATOR_OUTPUT_STATUS"], "r", 0.0)
        got = asm.add("AOA_SSA", p["AOA_SSA"], "r", 0.0)
        assert len(got) == 1 and abs(got[0].values["q"] - 0.1 * k * 57.29577951308232) < 1e-5


def _jittered_flight(
    h: float, n: int, seed: int, phase_us: int, jitter_us: int = 8_000, drift: float = 0.0
) -> list[tuple[int, str, tuple]]:
    """A real autopilot's messages of n samples: each part stamped at its sample's instant plus its own random
    0..jitter (the instant message too), the grid at an arbitrary phase of the vehicle's clock (boot time), the
    vehicle's period ``h * (1 + drift)``; in stamp order, as a ground station logs them. alpha = k tells the
    sample a part came from."""
    import random

    rng = random.Random(seed)
    out = []
    for k in range(n):
        base = phase_us + round(k * h * (1 + drift) * 1e6)
        t = {name: base + rng.randint(0, jitter_us) for name in ("AOA_SSA", "ATTITUDE", "ACTUATOR_OUTPUT_STATUS")}
        out += [
            (t["AOA_SSA"], "AOA_SSA", AOA.decode(AOA.unpacker.pack(t["AOA_SSA"], float(k), 0.0))),
            (
                t["ATTITUDE"],
                "ATTITUDE",
                ATT.decode(ATT.unpacker.pack((t["ATTITUDE"] // 1000) & 0xFFFFFFFF, 0, 0, 0, 0, 0.001 * k, 0)),
            ),
            (
                t["ACTUATOR_OUTPUT_STATUS"],
                "ACTUATOR_OUTPUT_STATUS",
                ACT.decode(ACT.unpacker.pack(t["ACTUATOR_OUTPUT_STATUS"], 1, -float(k), *[0.0] * 31)),
            ),
        ]
    return sorted(out, key=lambda m: m[0])


def _alpha_q_map():
    """The default map with q an output too, so that a sample needs all three parts (none may come late)."""
    import tomllib

    from monitor.link.signals import DEFAULT_SIGNALS_TOML, parse_signals

    table = tomllib.loads(DEFAULT_SIGNALS_TOML)["signals"]
    table["outputs"] = ["alpha", "q"]
    return parse_signals(table, "test", 2, 1)


def _assemble(h: float, messages) -> tuple[SampleAssembler, list]:
    asm = SampleAssembler(_alpha_q_map(), h, observe=True)
    got = []
    for t_us, name, values in messages:
        got += asm.add(name, values, None, t_us * 1e-6)
    return asm, got + asm.flush(float("inf"))


import pytest  # noqa: E402


@pytest.mark.parametrize("h", [0.02, 0.03, 0.05])
@pytest.mark.parametrize("seed", range(4))
def test_parts_stamped_0_to_8_ms_apart_make_one_sample_at_any_phase_of_the_grid(h: float, seed: int) -> None:
    """The rule for real logs (module docstring): every part is filed by its stamp on the vehicle's own sample
    grid, whose phase follows the instant messages; parts within h/2 of their grid instant join it."""
    import random

    phase = random.Random(100 + seed).randint(0, 3_600_000_000)  # boot time of the first sample, any us
    asm, got = _assemble(h, _jittered_flight(h, 300, seed, phase))
    c = asm.counters
    assert len(got) == 300 and (c.incomplete, c.duplicates, c.stale, c.late_parts) == (0, 0, 0, 0), c
    assert [s.k for s in got] == list(range(got[0].k, got[0].k + 300))
    for s in got:  # every part of a sample is that sample's own
        k = int(s.values["alpha"])
        assert s.values["elevator"] == -k and s.values["q"] == pytest.approx(0.001 * k * 57.29577951308232, rel=1e-5)
    assert [int(s.values["alpha"]) for s in got] == list(range(300))


@pytest.mark.parametrize("drift", [0.01, 0.02, -0.01])
def test_a_vehicle_period_off_h_by_1_or_2_percent_loses_no_sample_to_jitter(drift: float) -> None:
    """The grid's phase follows the instants: a vehicle clock 1-2 % off h (sample period 20.4 ms at h = 20 ms)
    with 0..8 ms jitter gives consecutive samples, none dropped, every part in its own sample."""
    asm, got = _assemble(0.02, _jittered_flight(0.02, 1000, 7, 5_000_000, drift=drift))
    c = asm.counters
    assert len(got) == 1000 and (c.incomplete, c.duplicates, c.late_parts) == (0, 0, 0), c
    assert [s.k for s in got] == list(range(got[0].k, got[0].k + 1000))
    assert all(int(s.values["alpha"]) == -s.values["elevator"] for s in got)


@pytest.mark.parametrize("period, h", [(0.02, 0.05), (0.01, 0.05), (0.02, 0.04)])
def test_instants_faster_than_h_are_decimated_on_a_fixed_grid(period: float, h: float) -> None:
    """A 50 Hz log read at h = 0.05 s: one sample per h (k never runs ahead of the vehicle's clock); the other
    instants of each h are duplicates, and they do not pull the grid."""
    n = 1000
    asm, got = _assemble(h, _jittered_flight(period, n, 3, 1_234_567, jitter_us=2000))
    expected = round(n * period / h)
    assert abs(len(got) - expected) <= 1 and got[-1].k - got[0].k + 1 == len(got)
    assert asm.counters.incomplete <= 2


def test_a_32_bit_time_usec_instant_is_unwrapped() -> None:
    """SERVO_OUTPUT_RAW's time_usec is 32-bit: it wraps after 71.6 min of boot; samples go on across it."""
    import tomllib

    from monitor.link.signals import parse_signals

    table = tomllib.loads(DEFAULT_SIGNALS_TOML)["signals"]
    table["instant"] = "SERVO_OUTPUT_RAW"
    table["measured"]["elevator"] = {"field": "SERVO_OUTPUT_RAW.servo2_raw", "scale": 0.06, "offset": -90.0}
    table["outputs"] = ["elevator"]
    smap = parse_signals(table, "test", 1, 1)
    assert smap.time_fields["SERVO_OUTPUT_RAW"][2] == 1 << 32
    servo = layout_by_name("SERVO_OUTPUT_RAW")
    asm = SampleAssembler(smap, H, observe=True)
    t0 = (1 << 32) - 60_000  # three samples before the wrap
    got = []
    for k in range(6):
        t = (t0 + k * 20_000) & 0xFFFFFFFF
        got += asm.add(
            "SERVO_OUTPUT_RAW", servo.decode(servo.unpacker.pack(t, 1500, 1500 + k, *[0] * 15)), None, float(k)
        )
    assert [s.values["elevator"] for s in got] == pytest.approx([0.06 * k for k in range(6)])
    assert [s.k for s in got] == list(range(got[0].k, got[0].k + 6))
