"""The one definition of a sample's messages: the vehicle's encoder and the monitor's link layer built from it
agree, field for field, for both kinds of sample (the linear plant's and an aircraft's)."""

from __future__ import annotations

import dataclasses
import math
import tomllib

import pytest

from monitor.link.assembly import SampleAssembler
from monitor.link.dialect import layout_by_id
from monitor.link.frames import FrameCounters, FrameParser
from monitor.link.signals import DEFAULT_SIGNALS_TOML, contract_signals_toml, parse_signals
from monitor.wire.mavlink import new_codec, sample_index
from monitor.wire.telemetry import SAMPLE_FIELDS, AircraftSample, Sample, encode_sample, quantities, wire_values

H = 0.05
AIRCRAFT = AircraftSample(
    sysid=3,
    k=7,
    t=0.35,
    alpha_deg=1.25,
    q_deg_s=-2.0,
    elevator_deg=4.3,
    theta_deg=3.0,
    airspeed_m_s=51.4,
    attitude=(0.01, 1.5, 0.002, -0.003),
    hud=(51.0, 86.0, 71.0, 914.4, -0.2),
)


def _through_the_link(data: bytes, names: list[str]) -> dict[str, float]:
    """Decode a datagram as the monitor does: frames -> layouts -> a signal map of ``names`` -> assembly."""
    table = tomllib.loads(contract_signals_toml(names, outputs=[n for n in names if n != "elevator"]))["signals"]
    smap = parse_signals(table, "test", outputs=len(names) - 1, inputs=1)
    asm = SampleAssembler(smap, H, observe=True)  # observe-only: the sample carries its actuator report
    got = []
    for msgid, _sysid, _compid, payload in FrameParser(FrameCounters()).feed(data):
        layout = layout_by_id(msgid)
        got += asm.add(layout.name, layout.decode(payload), "r", 0.0)
    got += asm.flush(1.0)
    [sample] = got
    assert sample.k == AIRCRAFT.k
    return sample.values


def test_an_aircraft_sample_encoded_by_the_vehicle_decodes_through_the_link_layer_to_its_quantities() -> None:
    data = encode_sample(new_codec(3, 1), AIRCRAFT, H)
    names = [f.name for f in SAMPLE_FIELDS if f.name != "elevator"] + ["elevator"]
    values = _through_the_link(data, names)
    expected = quantities(AIRCRAFT)
    assert set(values) == set(expected) == {f.name for f in SAMPLE_FIELDS}
    for name, value in expected.items():
        # float32 on the wire; VFR_HUD's heading and throttle are integers
        assert values[name] == pytest.approx(value, rel=1e-6, abs=1e-5), name
    assert values["roll"] == pytest.approx(math.degrees(0.01), rel=1e-6)  # radians on the wire, degrees out


def test_the_linear_plant_s_sample_is_the_default_map_s_three_messages() -> None:
    sample = Sample(sysid=1, k=7, t=7.0, alpha_deg=-0.5, q_deg_s=3.0, elevator_deg=-1.0)
    data = encode_sample(new_codec(1, 1), sample, H)
    kinds = [layout_by_id(m).name for m, *_ in FrameParser(FrameCounters()).feed(data)]
    assert kinds == ["ATTITUDE", "AOA_SSA", "ACTUATOR_OUTPUT_STATUS"]
    smap = tomllib.loads(DEFAULT_SIGNALS_TOML)["signals"]
    assert set(smap["measured"]) == {"alpha", "q", "elevator"} == set(quantities(sample))
    values = _through_the_link(data, ["alpha", "q", "elevator"])
    assert values == pytest.approx({"alpha": -0.5, "q": 3.0, "elevator": -1.0}, rel=1e-6)


def test_wire_values_are_what_the_encoder_puts_in_each_field() -> None:
    data = encode_sample(new_codec(3, 1), AIRCRAFT, H)
    msgs = {m.get_type(): m for m in new_codec(255, 190).parse_buffer(data)}
    for (message, field, index), value in wire_values(AIRCRAFT).items():
        sent = getattr(msgs[message], field)
        sent = sent if index is None else sent[index]
        assert sent == pytest.approx(value, rel=1e-6, abs=0.5 if field in ("heading", "throttle") else 1e-6)


def test_an_aircraft_sample_is_one_datagram_in_the_contract_s_order_stamped_with_its_instant() -> None:
    """ATTITUDE, AOA_SSA, VFR_HUD, ACTUATOR_OUTPUT_STATUS in one datagram; every timed message at k h; VFR_HUD's
    heading and throttle are whole numbers on the wire."""
    sample = dataclasses.replace(AIRCRAFT, hud=(51.0, 86.4, 71, 914.4, -0.2))
    msgs = {m.get_type(): m for m in new_codec(255, 190).parse_buffer(encode_sample(new_codec(3, 1), sample, H))}
    assert list(msgs)[:4] == ["ATTITUDE", "AOA_SSA", "VFR_HUD", "ACTUATOR_OUTPUT_STATUS"]
    att, aoa, hud, act = msgs["ATTITUDE"], msgs["AOA_SSA"], msgs["VFR_HUD"], msgs["ACTUATOR_OUTPUT_STATUS"]
    assert sample_index(aoa.time_usec, H) == 7 and att.time_boot_ms == 350 and act.time_usec == 350_000
    assert aoa.AOA == pytest.approx(1.25) and att.pitch == pytest.approx(math.radians(3.0))
    assert att.pitchspeed == pytest.approx(math.radians(-2.0)) and att.roll == pytest.approx(0.01)
    assert hud.airspeed == pytest.approx(51.4) and hud.heading == 86 and hud.throttle == 71
    assert hud.alt == pytest.approx(914.4) and act.actuator[0] == pytest.approx(4.3)
