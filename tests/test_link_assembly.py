"""Sample assembly: parts of one instant in any order, duplicates and late parts counted, bounded waits."""

from __future__ import annotations

import itertools

from monitor.link.assembly import SampleAssembler
from monitor.link.dialect import layout_by_name
from monitor.link.signals import default_signal_map

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
