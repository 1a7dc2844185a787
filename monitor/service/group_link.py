"""A monitor group over Zenoh: the member's token, its beats, its peers' tokens and beats, and state transfer.

Keys, under the contract's ``<prefix>/monitor/`` family (``<prefix>/monitor/<name>``, the monitor's own token,
stays as it is)::

    <prefix>/monitor/group/<group>/<member>          liveliness token, while the member's session is up
    <prefix>/monitor/group/<group>/<member>/beat     {"warm": [...], "cold": [...], "steps": {...}}, every 0.1 s
    <prefix>/monitor/group/<group>/<member>/state    queryable: {"<sysid>": state, ...} of its warm vehicles

Why the beats come from the loop and not from a thread: a beat says "this member's loop runs", which is what its
vehicles need; a thread would go on beating for a loop that is stuck. Why every Zenoh event goes through
``call_soon_threadsafe``: the view and the vehicle table belong to the loop; the Zenoh threads only stamp the
arrival time and hand over. The pure decisions are ``monitor.service.group``'s; the state copied is
``monitor.service.group_state``'s.
"""

from __future__ import annotations

import asyncio
import functools
import json
import logging
import time
import uuid
from typing import Any

import zenoh

from monitor.service.group import BEAT_S, GroupView
from monitor.service.group_state import export_state, import_state
from monitor.service.vehicles import VehicleTable

__all__ = ["GroupLink", "group_base"]

log = logging.getLogger("monitor.group")

_JSON = zenoh.Encoding.APPLICATION_JSON
QUERY_TIMEOUT_S = 1.0


def group_base(prefix: str, group: str) -> str:
    """``<prefix>/monitor/group/<group>``: where the members' tokens, beats and states live."""
    return f"{prefix.rstrip('/')}/monitor/group/{group}"


class GroupLink:
    """One member's Zenoh side; ``start`` (in the loop) declares the subscriptions and starts beating."""

    def __init__(self, session: zenoh.Session, prefix: str, group: str, view: GroupView, table: VehicleTable) -> None:
        self.session = session
        self.group = group
        self.view = view
        self.table = table
        self.base = group_base(prefix, group)
        self.member = view.member
        self.token = session.liveliness().declare_token(f"{self.base}/{self.member}")
        self.beats = session.declare_publisher(f"{self.base}/{self.member}/beat", encoding=_JSON)
        self._entities: list[Any] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._tick: asyncio.TimerHandle | None = None
        self._query_until = 0.0  # a state query is in flight until then
        self._live: tuple[str, ...] = ()
        self._announced = False
        self._stalls_logged = 0
        self.instance = uuid.uuid4().hex[:12]  # tells this process's beats from another's under the same name
        self._twins: set[str] = set()

    # -- Zenoh threads: stamp, hand over ---------------------------------------------------------------
    def _later(self, fn, *args) -> None:
        loop = self._loop
        if loop is None:
            return
        try:
            loop.call_soon_threadsafe(fn, *args)
        except RuntimeError:  # the loop closed while Zenoh delivered: nothing to update any more
            pass

    def _on_token(self, sample: zenoh.Sample) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        self._later(self.view.token, name, sample.kind == zenoh.SampleKind.PUT)

    def _on_beat(self, sample: zenoh.Sample) -> None:
        now = time.monotonic()
        name = str(sample.key_expr).split("/")[-2]
        try:
            d = json.loads(sample.payload.to_bytes())
            if name == self.member:
                if d.get("instance") != self.instance:
                    self._later(self._twin, str(d.get("instance")))
                return
            warm, cold = [int(s) for s in d["warm"]], [int(s) for s in d["cold"]]
            steps = {int(s): (int(k), str(digest)) for s, (k, digest) in d.get("steps", {}).items()}
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            log.debug("ignoring a beat from %s: %s", name, exc)
            return
        self._later(self._peer_beat, name, warm, cold, now, steps)

    def _on_query(self, query: zenoh.Query) -> None:
        self._later(self._answer, query)

    def _on_reply(self, plan: dict[int, str], reply: zenoh.Reply) -> None:
        if reply.ok is None:
            return
        name = str(reply.ok.key_expr).split("/")[-2]
        try:
            data = json.loads(reply.ok.payload.to_bytes())
        except ValueError as exc:
            log.debug("ignoring a state reply from %s: %s", name, exc)
            return
        self._later(self._adopt, plan, name, data)

    # -- the loop -------------------------------------------------------------------------------------
    def _twin(self, instance: str) -> None:
        """Another process beats under this member's name: both would answer the same vehicles (one ERROR each)."""
        if instance not in self._twins:
            self._twins.add(instance)
            log.error(
                "group '%s': another process uses this member's name '%s': both answer the same vehicles and their "
                "peers cannot tell them apart; give every member its own --name",
                self.group,
                self.member,
            )

    def _peer_beat(self, name: str, warm: list[int], cold: list[int], now: float, steps: dict) -> None:
        out = self.view.beat(name, warm, cold, now, steps)
        if out:  # one line per beat, not per vehicle: under overload many vehicles can be out of step at once
            log.warning(
                "group '%s': out of step with their owner '%s' (a sample one of the two shed or completed without "
                "its actuator report): %s; copying the owner's state",
                self.group,
                name,
                _vehicles(f"vehicle {sysid} at k={k}" for sysid, k in out),
            )

    def start(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        now = time.monotonic()
        self.view.last_tick = now
        self.view.quiet_since = now  # listen from here, not from the process start
        session = self.session
        self._entities = [
            session.liveliness().declare_subscriber(f"{self.base}/*", self._on_token, history=True),
            session.declare_subscriber(f"{self.base}/*/beat", self._on_beat),
            session.declare_queryable(f"{self.base}/{self.member}/state", self._on_query),
        ]
        self._beat()

    def _beat(self) -> None:
        view = self.view
        now = time.monotonic()
        view.tick(now)
        if view.stalls > self._stalls_logged:  # found here or, first, by the loop's next sample after the stall
            self._stalls_logged = view.stalls
            log.warning(
                "group '%s': this member was stalled for %.2f s (its peers count it dead after %.2f s): it answers "
                "nothing until its estimators are in step with the group again",
                self.group,
                view.stalled_for,
                view.silence_s,
            )
        view.forget(self.table.vehicles)
        self._send_beat(now)
        self._report(now)
        if view.cold and now >= self._query_until:
            plan = view.sync_plan(now)
            for source in sorted(set(plan.values())):
                self._query_until = now + QUERY_TIMEOUT_S
                wanted = {sysid: s for sysid, s in plan.items() if s == source}
                try:
                    key = f"{self.base}/{source}/state"
                    self.session.get(key, functools.partial(self._on_reply, wanted), timeout=QUERY_TIMEOUT_S)
                except Exception as exc:
                    log.debug("state query to %s failed: %s", source, exc)
        assert self._loop is not None
        self._tick = self._loop.call_later(BEAT_S, self._beat)

    def _send_beat(self, now: float) -> None:
        try:
            self.beats.put(json.dumps({**self.view.beat_payload(now), "instance": self.instance}))
        except Exception as exc:  # a closing session costs a beat, not the loop
            log.debug("beat not sent: %s", exc)

    def _report(self, now: float) -> None:
        """INFO when this member is first in step (the ready line of a group) and whenever the live set changes."""
        view = self.view
        live = tuple(view.live_peers(now))
        if not view.settled():
            return
        if not self._announced:
            self._announced = True
            log.info(
                "group '%s': member '%s' in step; live peers: %s", self.group, self.member, ", ".join(live) or "none"
            )
        elif live != self._live:
            gone = sorted(set(self._live) - set(live))
            came = sorted(set(live) - set(self._live))
            log.info(
                "group '%s': live peers %s%s%s",
                self.group,
                ", ".join(live) or "none",
                f"; gone: {', '.join(gone)}" if gone else "",
                f"; back or new: {', '.join(came)}" if came else "",
            )
        self._live = live

    def _answer(self, query: zenoh.Query) -> None:
        """A peer asks for the states of this member's warm vehicles (it is cold on some of them)."""
        try:
            states = {}
            for sysid, vehicle in self.table.vehicles.items():
                if sysid in self.view.warm:
                    state = export_state(vehicle)
                    if state is not None:
                        states[str(sysid)] = state
            query.reply(f"{self.base}/{self.member}/state", json.dumps(states), encoding=_JSON)
        except Exception as exc:
            log.debug("state query not answered: %s", exc)
        finally:
            query.drop()

    def _adopt(self, plan: dict[int, str], source: str, data: dict[str, Any]) -> None:
        """Copy the states the plan wanted from ``source``; a vehicle at another sample waits for the next beat."""
        self._query_until = 0.0
        adopted = []
        for sysid, wanted_from in plan.items():
            state = data.get(str(sysid))
            vehicle = self.table.vehicles.get(sysid)
            if wanted_from != source or state is None or vehicle is None or sysid not in self.view.cold:
                continue
            if import_state(vehicle, state):
                self.view.adopted(sysid, state["k"], vehicle.state)
                adopted.append(f"vehicle {sysid} at k={state['k']}")
        if adopted:  # say so now, not at the next beat: the owner stops answering within a message's time
            self._send_beat(time.monotonic())
            log.info(
                "group '%s': in step again (estimator state copied from '%s'): %s",
                self.group,
                source,
                _vehicles(adopted),
            )

    def stop(self) -> None:
        """Stop beating and handing Zenoh events to the loop (the loop is ending)."""
        if self._tick is not None:
            self._tick.cancel()
            self._tick = None
        self._loop = None

    def close(self) -> list[Any]:
        """``stop``, and the entities to undeclare (before the session closes)."""
        self.stop()
        return [*self._entities, self.beats, self.token]


def _vehicles(items, most: int = 8) -> str:
    """``vehicle 1 at k=5, vehicle 2 at k=5`` (the first ``most``, then how many more)."""
    items = list(items)
    more = f" and {len(items) - most} more" if len(items) > most else ""
    return ", ".join(items[:most]) + more
