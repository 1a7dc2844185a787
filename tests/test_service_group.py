"""A monitor group's pure pieces (monitor/service/group.py, group_state.py): the rendezvous hashing, the liveness
tracker with an injected clock, the warm/cold rules, and the state a resumed member copies."""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from monitor.service.alarm import AlarmConfig
from monitor.service.fleet_file import Fleet, load_model
from monitor.service.group import BEAT_S, GRACE_S, SETTLE_S, SILENCE_S, GroupView, owner, state_digest, weight
from monitor.service.group_state import export_state, import_state
from monitor.service.vehicles import VehicleTable
from tests.vehicle_table import feed

MEMBERS = ["ground-a", "ground-b", "ground-c", "laptop-1", "edge-7"]
VEHICLES = [(prefix, sysid) for prefix in ("uav", "uav/north", "uav/south", "uav/west") for sysid in range(1, 256)]


def _assign(members: list[str]) -> dict[tuple[str, int], str | None]:
    return {(prefix, sysid): owner(prefix, sysid, members) for prefix, sysid in VEHICLES}


def test_the_weight_is_the_same_in_every_process() -> None:
    """Python's ``hash`` of a str is salted per process; the weight must not be (every member computes it)."""
    code = "from monitor.service.group import weight; print(weight('uav', 7, 'ground-a'), weight('uav/x', 200, 'b'))"
    outs = {
        subprocess.run(
            [sys.executable, "-c", code],
            env={"PYTHONHASHSEED": seed, "PATH": ""},
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parent.parent,
        ).stdout
        for seed in ("1", "2", "random")
    }
    assert outs == {f"{weight('uav', 7, 'ground-a')} {weight('uav/x', 200, 'b')}\n"}
    assert weight("uav", 7, "ground-a") != weight("uav", 7, "ground-b") != weight("uav/x", 7, "ground-b")


def test_vehicles_are_spread_evenly() -> None:
    counts = Counter(_assign(MEMBERS).values())
    mean = len(VEHICLES) / len(MEMBERS)
    assert set(counts) == set(MEMBERS)
    assert all(abs(n - mean) < 0.15 * mean for n in counts.values()), counts


def test_a_member_leaving_moves_its_vehicles_only() -> None:
    before = _assign(MEMBERS)
    after = _assign([m for m in MEMBERS if m != "ground-b"])
    moved = {v for v in before if before[v] != after[v]}
    assert moved == {v for v, m in before.items() if m == "ground-b"}
    assert len(Counter(after[v] for v in moved)) == len(MEMBERS) - 1  # spread over every survivor, not one heir


def test_a_member_joining_takes_only_its_own_share() -> None:
    before = _assign(MEMBERS)
    after = _assign([*MEMBERS, "newcomer"])
    moved = {v for v in before if before[v] != after[v]}
    assert moved and all(after[v] == "newcomer" for v in moved)
    assert abs(len(moved) - len(VEHICLES) / (len(MEMBERS) + 1)) < 0.15 * len(VEHICLES) / (len(MEMBERS) + 1)


def test_no_member_owns_nothing() -> None:
    assert owner("uav", 1, []) is None


# -- the view, on an injected clock ------------------------------------------------------------------------------


def _settled_view(member: str, peers: list[str], t: float = 0.0) -> GroupView:
    """A member that heard every peer's token and beats until it settled, at time ``t + SETTLE_S``."""
    view = GroupView(member, now=t)
    for p in peers:
        view.token(p, True)
    step = t
    while step <= t + SETTLE_S + 1e-9:
        for p in peers:
            view.beat(p, [], [], step)
        view.tick(step)
        step += BEAT_S / 2
    assert view.settled()
    return view


def _beat_all(view: GroupView, warm: dict[str, list[int]], now: float) -> None:
    for p, sysids in warm.items():
        view.beat(p, sysids, [], now)


def _run(view: GroupView, warm: dict[str, list[int]], until: float) -> None:
    """Time passes normally up to ``until``: the member ticks and the peers in ``warm`` beat every half beat."""
    now = view.last_tick
    while now < until - 1e-9:
        now = min(until, now + BEAT_S / 2)
        _beat_all(view, warm, now)
        view.tick(now)


def _sysid_owned_by(member: str, members: list[str]) -> int:
    return next(s for s in range(1, 256) if owner("uav", s, members) == member)


def test_a_new_vehicle_is_answered_by_its_owner_alone_from_its_first_sample() -> None:
    """Before the peers' beats can list it, every member counts them in (the grace): exactly one answers."""
    members = ["a", "b", "c"]
    t = 1.0
    views = {m: _settled_view(m, [p for p in members if p != m], 0.0) for m in members}
    for m, v in views.items():
        _run(v, {p: [] for p in members if p != m}, t)
    sysid = _sysid_owned_by("b", members)
    answering = [m for m, v in views.items() if v.serves(sysid, t)]
    assert answering == ["b"]
    # after the grace a peer that never listed the vehicle (it does not receive it) is not counted
    view = views["a"]
    later = t + GRACE_S + 0.01
    _run(view, {"b": [], "c": []}, later)
    assert view.serves(sysid, later)


def test_a_hung_peer_is_dead_after_the_silence_and_back_when_it_beats() -> None:
    members = ["a", "b", "c"]
    sysid = next(s for s in range(1, 256) if owner("uav", s, members) == "b" and owner("uav", s, ["a", "c"]) == "a")
    view = _settled_view("a", ["b", "c"])
    t = 1.0
    _run(view, {"b": [], "c": []}, t)
    assert not view.serves(sysid, t) and sysid in view.warm  # new to everyone: warm everywhere, b answers
    _run(view, {"b": [sysid], "c": [sysid]}, t + BEAT_S)
    t += BEAT_S
    assert view.owner_of(sysid, t) == "b" and not view.serves(sysid, t)
    # b hangs: its token stays, its beats stop; c goes on beating, a ticks
    for i in range(1, 8):
        now = t + i * BEAT_S
        _beat_all(view, {"c": [sysid]}, now)
        view.tick(now)
        expected = "b" if i * BEAT_S <= SILENCE_S else "a"
        assert view.owner_of(sysid, now) == expected, (i, view.owner_of(sysid, now))
        assert view.serves(sysid, now) == (expected == "a")
    # b resumes: warm again (it copied the state), it owns the vehicle again at its first beat
    now = t + 8 * BEAT_S
    _beat_all(view, {"b": [sysid], "c": [sysid]}, now)
    assert view.owner_of(sysid, now) == "b"


def test_a_killed_peers_token_drop_moves_its_vehicles_at_once() -> None:
    members = ["a", "b", "c"]
    sysid = _sysid_owned_by("b", members)
    view = _settled_view("a", ["b", "c"])
    _run(view, {"b": [sysid], "c": [sysid]}, 1.0)
    view.see(sysid, 1.0)
    assert view.owner_of(sysid, 1.0) == "b"
    view.token("b", False)
    assert view.owner_of(sysid, 1.0) == owner("uav", sysid, ["a", "c"])
    view.token("b", True)  # a restarted process under the same name: live at its first beat, not before
    assert view.owner_of(sysid, 1.0) != "b"
    _beat_all(view, {"b": [sysid]}, 1.05)
    assert view.owner_of(sysid, 1.05) == "b"


def test_a_stalled_member_answers_nothing_until_it_copied_the_owners_state() -> None:
    members = ["a", "b"]
    sysid = _sysid_owned_by("a", members)
    view = _settled_view("a", ["b"])
    t = 1.0
    _run(view, {"b": []}, t)
    assert view.serves(sysid, t)  # a new vehicle for both, a is its owner
    _run(view, {"b": [sysid]}, t + 0.5)
    t += 0.5
    assert view.serves(sysid, t)
    # stopped for 0.8 s: the first sample after it finds the stall before it answers
    t2 = t + 0.8
    _beat_all(view, {"b": [sysid]}, t2)  # the peer's beats, delivered on resume
    assert not view.serves(sysid, t2)
    assert view.stalls == 1 and math.isclose(view.stalled_for, 0.8) and sysid in view.cold
    assert view.sync_plan(t2) == {}  # listening first
    now = t2
    while not view.settled():
        now += BEAT_S
        _beat_all(view, {"b": [sysid]}, now)
        view.tick(now)
        assert not view.serves(sysid, now)
    assert view.sync_plan(now) == {sysid: "b"}
    view.adopted(sysid)
    payload = view.beat_payload(now)
    assert view.serves(sysid, now) and (payload["warm"], payload["cold"]) == ([sysid], [])
    assert view.stalls == 1


def test_without_a_warm_peer_only_one_member_keeps_its_own_state() -> None:
    """A group started mid-flight: every member is cold on the vehicle; the owner among those who know it goes on
    from its own state and the others copy it."""
    members = ["a", "b", "c"]
    sysid = 42
    views = {m: GroupView(m, now=0.0) for m in members}
    t = 0.0
    for v in views.values():
        v.see(sysid, t)  # heard while listening: cold
    while t < SETTLE_S + BEAT_S:
        t += BEAT_S / 2
        for m, v in views.items():
            for p in members:
                if p != m:
                    v.token(p, True)
                    v.beat(p, [], [sysid], t)
            v.tick(t)
    plans = {m: v.sync_plan(t) for m, v in views.items()}
    keeper = owner("uav", sysid, members)
    assert [m for m, v in views.items() if sysid in v.warm] == [keeper]
    assert all(plans[m] == {} for m in members)  # nobody to copy from yet
    for m, v in views.items():
        if m != keeper:
            v.beat(keeper, [sysid], [], t)
            assert v.sync_plan(t) == {sysid: keeper}


def test_expired_vehicles_are_forgotten() -> None:
    view = _settled_view("a", [])
    view.see(3, 1.0)
    view.see(4, 1.0)
    view.forget([4])
    payload = view.beat_payload(1.0)
    assert (payload["warm"], payload["cold"], payload["steps"]) == ([4], [], {})


class _State:
    """An estimator state as the digest sees it."""

    def __init__(self, z: list[float], f_reported: list[float] | None = None) -> None:
        self.z = np.array(z)
        self.f_reported = f_reported


def test_a_warm_member_out_of_step_with_the_owner_turns_cold_and_copies_it() -> None:
    """The owner's beat carries its last step (k, digest); a warm member that stepped the same k to another state
    (one of them shed that sample) is cold until it copied the owner's state, and then compares equal again."""
    members = ["a", "b"]
    sysid = _sysid_owned_by("b", members)
    owner_view, warm_view = _settled_view("b", ["a"]), _settled_view("a", ["b"])
    _run(owner_view, {"a": []}, 1.0)
    _run(warm_view, {"b": []}, 1.0)
    assert owner_view.serves(sysid, 1.0) and not warm_view.serves(sysid, 1.0)
    for k, (zo, zw) in enumerate([([0.1, 0.2], [0.1, 0.2]), ([0.3, 0.4], [0.3, 0.4]), ([0.5, 0.6], [0.5, 0.61])]):
        owner_view.stepped(sysid, k, _State(zo))
        warm_view.stepped(sysid, k, _State(zw))
        beat = owner_view.beat_payload(1.0)
        steps = {int(s): (k_, d) for s, (k_, d) in beat["steps"].items()}
        assert steps == {sysid: (k, owner_view.steps[sysid][-1][1])}
        out = warm_view.beat("b", beat["warm"], beat["cold"], 1.0, steps)
        assert out == ([] if k < 2 else [(sysid, 2)])
    assert sysid in warm_view.cold and warm_view.out_of_step == 1 and warm_view.sync_plan(1.0) == {sysid: "b"}
    warm_view.adopted(sysid, 2, _State([0.5, 0.6]))  # the owner's state, copied
    assert warm_view.beat("b", [sysid], [], 1.0, steps) == []  # the owner's beat again: in step now
    # a step the member never made (older than its history, or not yet) is not judged
    assert warm_view.beat("b", [sysid], [], 1.0, {sysid: (99, "0" * 16)}) == [] and sysid in warm_view.warm
    # the digest sees f_reported too
    assert state_digest(_State([1.0], [0.5])) != state_digest(_State([1.0], [0.25])) != state_digest(_State([1.0]))


# -- the state a member copies ------------------------------------------------------------------------------------


def _table(gains_path: Path) -> VehicleTable:
    return VehicleTable(Fleet(load_model("paper-continuous", gains_path)), AlarmConfig(threshold=0.05, clear=0.01))


def test_a_copied_state_steps_to_the_same_bits(gains_path: Path) -> None:
    """Two tables on the same samples, one of them with a gap (a stalled member): after copying the other's state
    at the same sample, every later estimate and command is bit for bit the same."""
    owner_table, resumed = _table(gains_path), _table(gains_path)
    alphas = [0.1 * math.sin(0.7 * k) + (0.5 if k >= 6 else 0.0) for k in range(30)]
    for k in range(12):
        feed(owner_table, 1, k, "A", k * 0.01, alpha=alphas[k])
        if not 5 <= k <= 9:  # the resumed member missed 5..9
            feed(resumed, 1, k, "A", k * 0.01, alpha=alphas[k])
    a, b = owner_table.vehicles[1], resumed.vehicles[1]
    assert a.state.z.tolist() != b.state.z.tolist()
    data = export_state(a)
    assert data is not None
    assert import_state(b, json.loads(json.dumps(data)))  # through JSON, as over Zenoh
    assert b.alarm.raised == a.alarm.raised
    for k in range(12, 30):
        pa = feed(owner_table, 1, k, "A", k * 0.01, alpha=alphas[k])
        pb = feed(resumed, 1, k, "A", k * 0.01, alpha=alphas[k])
        assert pa.result.f_hat.tolist() == pb.result.f_hat.tolist()
        assert pa.u_abs == pb.u_abs and pa.alarm_event == pb.alarm_event


def test_a_state_from_another_sample_is_not_copied(gains_path: Path) -> None:
    ahead, behind = _table(gains_path), _table(gains_path)
    for k in range(5):
        feed(ahead, 1, k, "A", 0.0)
        if k < 4:
            feed(behind, 1, k, "A", 0.0)
    data = export_state(ahead.vehicles[1])
    before = behind.vehicles[1].state.z.tolist()
    assert data is not None and not import_state(behind.vehicles[1], data)
    assert behind.vehicles[1].state.z.tolist() == before


@pytest.mark.parametrize("name", ["m1", "ground.a-1_x"])
def test_names_are_one_key_chunk(name: str) -> None:
    from monitor.service.group_link import group_base

    assert group_base("uav/", name) == f"uav/monitor/group/{name}"


@pytest.mark.parametrize("flags", [["--group", "a/b"], ["--group", "ok", "--name", "x*"]])
def test_a_group_or_member_name_that_is_no_key_chunk_is_one_line(gains_path: Path, flags: list[str]) -> None:
    base = [sys.executable, "-m", "monitor", "run", "--plant", "paper-continuous", "--gains", str(gains_path)]
    result = subprocess.run([*base, *flags], capture_output=True, text=True, timeout=60)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "Zenoh key" in result.stderr


def test_members_on_zenoh_see_each_other_and_a_second_process_under_one_name_is_an_error(
    gains_path: Path, caplog
) -> None:
    """The wiring on a real Zenoh session (in process): two members see each other's tokens and beats within a few
    beats; a third link under an existing name is reported."""
    import asyncio

    from monitor.service.group_link import GroupLink
    from monitor.wire.zenoh_session import build_config, close_quietly, open_session

    session = open_session(build_config())
    links: list[GroupLink] = []

    async def run() -> None:
        loop = asyncio.get_running_loop()
        now = time.monotonic()
        for name in ("a", "b", "a"):
            link = GroupLink(session, "uav", "t", GroupView(name, now=now), _table(gains_path))
            link.start(loop)
            links.append(link)
        await asyncio.sleep(4 * BEAT_S)

    try:
        with caplog.at_level("INFO", logger="monitor.group"):
            asyncio.run(run())
    finally:
        entities = [e for link in links for e in link.close()]
        close_quietly(session, *entities)
    now = time.monotonic()
    assert links[0].view.live_peers(now) == ["b"] and links[1].view.live_peers(now) == ["a"]
    errors = [r.message for r in caplog.records if r.levelname == "ERROR"]
    assert errors and all("another process uses this member's name 'a'" in e for e in errors)
    assert any("member 'b' in step; live peers: a" in r.message for r in caplog.records)
