"""A monitor group's membership, liveness and assignment, as pure logic: no Zenoh, no loop, the clock passed in.

Several ``fault-monitor run --group NAME`` processes receive the same telemetry (a router fans it out). Each
vehicle is answered (command, GCS feedback, Zenoh estimate and alarm) by exactly one member, its *owner*; the
others step its estimator on the same samples and stay silent (*warm*), so that whoever takes over goes on from
the same state. ``monitor.service.group_link`` wires this to Zenoh (tokens, beats, state transfer) and the loop.

Who is live, seen from one member (``GroupView``):

* a peer is live while its liveliness token is there AND its last beat (one every ``BEAT_S``) is at most
  ``silence_s`` old. The token alone would do for a killed process (it drops with the TCP link, in
  milliseconds), but a hung one (SIGSTOP, a stuck loop) keeps its link and its token for the lease (seconds):
  its beats stop, so it is dead to the assignment ``silence_s`` after its last beat;
* the member itself is live unless *stalled*: its own beat timer last ran more than ``silence_s`` ago. A member
  that was stopped finds out on its first look at the clock after it resumes, before it answers anything, and
  since its peers measure the same silence from a later instant (the beat's arrival, not its departure), it
  always knows itself dead no later than they do.

Who owns a vehicle: rendezvous (highest-random-weight) hashing of ``(prefix, sysid)`` over the live members that
are *warm* for it (``owner``): every member computes the same answer from the same view, a member's departure
moves only its own vehicles (to whichever live member ranks next for each), and an arrival takes back only the
vehicles it ranks first for. The weight is BLAKE2b of the names (Python's ``hash`` is salted per process).

Warm and cold, per vehicle: a member is warm for a vehicle while its estimator is in step with the group's
(it saw the same samples from the vehicle's first one, or it copied the state of the warm owner). A vehicle first
heard while a peer already knows it, and every vehicle of a member that stalled, is *cold*: that member computes,
records, never answers it, until it has copied the owner's state (``group_link``) or no live peer is warm for it.
A member's beat lists its warm and cold vehicles, so the owner is computed over warm members only; a resumed
member therefore takes its vehicles back only once their estimators are the owner's again, and the commands that
two members may both send for one sample in the handover (each from its own view, for the milliseconds a beat
takes) are the same command.

Out of step: two warm members differ when one of them shed a sample (or completed it without its actuator
report) and the other did not. The owner's beat carries its last step, ``(k, state_digest)``; a warm member that
remembers another digest for that k turns cold and copies the owner's state (``GroupView.beat``), so a difference
lasts about one beat.

After a start or a stall a member first listens for ``settle_s`` (it hears every live peer's beat) before it
judges anything warm on its own.
"""

from __future__ import annotations

import hashlib
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

__all__ = ["BEAT_S", "SILENCE_S", "SETTLE_S", "GRACE_S", "state_digest", "weight", "owner", "Peer", "GroupView"]

BEAT_S = 0.1  # a member's beat period
SILENCE_S = 0.5  # a member silent this long is dead to the assignment (5 beats: a busy machine stalls a loop 0.35 s)
SETTLE_S = 0.15  # after a start or a stall: listen this long (every live peer beats in it) before judging alone
GRACE_S = 0.3  # a vehicle this new here: a live peer that does not list it yet is presumed to start it too
HISTORY = 64  # steps remembered per vehicle to compare with the owner's (1.3 s at 50 Hz; beats come every 0.1 s)


def weight(prefix: str, sysid: int, member: str) -> int:
    """The member's rendezvous weight for a vehicle: 64 bits of BLAKE2b, the same in every process and version."""
    text = f"{prefix.rstrip('/')}\0{sysid}\0{member}".encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "big")


def owner(prefix: str, sysid: int, members: Iterable[str]) -> str | None:
    """The member that answers ``sysid``: the highest weight (ties, of 64-bit hashes, by name); None when none."""
    best: tuple[int, str] | None = None
    for m in members:
        key = (weight(prefix, sysid, m), m)
        if best is None or key > best:
            best = key
    return None if best is None else best[1]


def state_digest(state: Any) -> str:
    """64 bits of BLAKE2b over an estimator state's bytes (``z`` and the low-passed f_hat): equal states, equal
    digests; two members in step have the same digest after the same step."""
    h = hashlib.blake2b(state.z.tobytes(), digest_size=8)
    if state.f_reported is not None:
        h.update(repr(state.f_reported).encode())
    return h.hexdigest()


@dataclass
class Peer:
    """What one member knows of another: its token, its last beat (local receive time) and what it said."""

    token: bool = False
    beat_at: float | None = None
    warm: frozenset[int] = field(default_factory=frozenset)
    cold: frozenset[int] = field(default_factory=frozenset)

    def live(self, now: float, silence_s: float) -> bool:
        return self.token and self.beat_at is not None and now - self.beat_at <= silence_s


class GroupView:
    """One member's view of its group (its own warm/cold vehicles, its peers) and the decisions made from it.

    Called from one thread (the loop); times are ``time.monotonic()`` seconds passed in by the caller.
    """

    def __init__(
        self,
        member: str,
        prefix: str = "uav",
        *,
        now: float,
        silence_s: float = SILENCE_S,
        settle_s: float = SETTLE_S,
    ) -> None:
        self.member = member
        self.prefix = prefix
        self.silence_s = silence_s
        self.settle_s = settle_s
        self.peers: dict[str, Peer] = {}
        self.warm: set[int] = set()
        self.cold: set[int] = set()
        self.grace_s = GRACE_S
        self.first_seen: dict[int, float] = {}  # vehicle -> when this member first saw it
        self.steps: dict[int, deque[tuple[int, str]]] = {}  # vehicle -> its last (k, state digest) here
        self.out_of_step = 0  # warm vehicles found out of step with their owner (and copied again)
        self.last_tick = now
        self.quiet_since: float | None = now  # listening (a start or a stall); None once settled
        self.stalls = 0  # how many times this member found itself stalled
        self.stalled_for = 0.0  # the last stall's length, seconds
        self._cache: dict[int, tuple[tuple, str | None]] = {}  # sysid -> (the view it was computed on, owner)
        self._version = 0  # bumped whenever a warm set changes

    # -- peers (events from Zenoh, handed to the loop) ---------------------------------------------------
    def token(self, member: str, alive: bool) -> None:
        if member == self.member:
            return
        peer = self.peers.setdefault(member, Peer())
        peer.token = alive
        if not alive:
            peer.beat_at = None  # a token that comes back (a restarted process) is live at its first beat only

    def beat(
        self,
        member: str,
        warm: Iterable[int],
        cold: Iterable[int],
        now: float,
        steps: Mapping[int, tuple[int, str]] | None = None,
    ) -> list[tuple[int, int]]:
        """A peer's beat; ``steps``: the (k, state digest) of the vehicles it answers. Returns the vehicles this
        member was warm for and found out of step with that owner at the same k, as ``(sysid, k)``: they are cold
        now (a sample one of the two shed or completed without its actuator report), and copied again."""
        if member == self.member:
            return []
        peer = self.peers.setdefault(member, Peer())
        peer.beat_at = now
        warm_set, cold_set = frozenset(warm), frozenset(cold)
        if warm_set != peer.warm:
            self._version += 1
        peer.warm, peer.cold = warm_set, cold_set
        out: list[tuple[int, int]] = []
        for sysid, (k, digest) in (steps or {}).items():
            if sysid not in self.warm or self.owner_of(sysid, now) != member:
                continue
            mine = next((d for kk, d in self.steps.get(sysid, ()) if kk == k), None)
            if mine is not None and mine != digest:
                self.warm.discard(sysid)
                self.cold.add(sysid)
                self._version += 1
                self.out_of_step += 1
                out.append((sysid, k))
        return out

    def stepped(self, sysid: int, k: int, state: Any) -> None:
        """This member stepped ``sysid`` at ``k`` (``state``: its ``EstimatorState`` after the step): remembered to be
        compared with the owner's beat (the owner's own steps go in its beats)."""
        history = self.steps.get(sysid)
        if history is None:
            history = self.steps[sysid] = deque(maxlen=HISTORY)
        history.append((k, state_digest(state)))

    def live_peers(self, now: float) -> list[str]:
        return sorted(name for name, p in self.peers.items() if p.live(now, self.silence_s))

    # -- this member ------------------------------------------------------------------------------------
    def stalled(self, now: float) -> bool:
        """Whether this member's own beats stopped for longer than a peer waits: its peers count it dead now."""
        return now - self.last_tick > self.silence_s

    def _check_stall(self, now: float) -> bool:
        if not self.stalled(now):
            return False
        self.stalls += 1
        self.stalled_for = now - self.last_tick
        self.cold |= self.warm
        if self.warm:
            self.warm.clear()
            self._version += 1
        self.quiet_since = now
        self.last_tick = now  # the stall is handled; listening starts now
        return True

    def tick(self, now: float) -> bool:
        """The beat timer ran (just before this member beats); returns whether it found a stall (all cold)."""
        stalled = self._check_stall(now)
        self.last_tick = now
        if self.quiet_since is not None and now - self.quiet_since >= self.settle_s:
            self.quiet_since = None
        return stalled

    def settled(self) -> bool:
        return self.quiet_since is None

    def _peer_knows(self, sysid: int, now: float) -> bool:
        return any(sysid in p.warm or sysid in p.cold for p in self.peers.values() if p.live(now, self.silence_s))

    def see(self, sysid: int, now: float) -> None:
        """A vehicle's sample is here: a vehicle new to this member is warm if no live peer knows it yet (everyone
        starts it from the same first sample) and this member is settled; else cold."""
        if sysid in self.warm or sysid in self.cold:
            return
        self.first_seen[sysid] = now
        if self.settled() and not self._peer_knows(sysid, now):
            self.warm.add(sysid)
            self._version += 1
        else:
            self.cold.add(sysid)

    def forget(self, keep: Iterable[int]) -> None:
        """Vehicles the table no longer has (expired): neither warm nor cold."""
        keep = set(keep)
        if not self.warm <= keep:
            self._version += 1
        self.warm &= keep
        self.cold &= keep
        for table in (self.first_seen, self.steps):
            for sysid in [s for s in table if s not in keep]:
                del table[sysid]

    def owner_of(self, sysid: int, now: float) -> str | None:
        """The member that answers ``sysid`` in this view: rendezvous over the live members warm for it.

        A vehicle first seen here less than ``grace_s`` ago counts the live peers that do not list it at all as
        warm too: they get the same telemetry and start it from the same first sample, but their beats cannot say
        so yet (without this every member would answer a new vehicle's first samples). After the grace, a peer
        that never lists it does not receive it, and is not counted."""
        new = now - self.first_seen.get(sysid, now) < self.grace_s
        live = tuple(
            name
            for name, p in self.peers.items()
            if p.live(now, self.silence_s) and (sysid in p.warm or (new and sysid not in p.cold))
        )
        mine = sysid in self.warm and not self.stalled(now)
        key = (live, mine, self._version)
        hit = self._cache.get(sysid)
        if hit is not None and hit[0] == key:
            return hit[1]
        result = owner(self.prefix, sysid, (*live, self.member) if mine else live)
        self._cache[sysid] = (key, result)
        return result

    def serves(self, sysid: int, now: float) -> bool:
        """Whether this member answers this sample of ``sysid`` (the loop asks once per processed sample)."""
        self._check_stall(now)
        self.see(sysid, now)
        return sysid in self.warm and self.owner_of(sysid, now) == self.member

    # -- state transfer ---------------------------------------------------------------------------------
    def sync_plan(self, now: float) -> dict[int, str]:
        """Once settled: for each cold vehicle, the live peer to copy its state from (its owner among the warm
        peers). When no live peer is warm for it (a group started mid-flight, or all of it stalled), one member
        keeps its own state, the owner among the live members that know the vehicle: this one, which then becomes
        warm on it, or another, which this one copies once that one says it is warm. Only one state goes on."""
        if not self.settled():
            return {}
        plan: dict[int, str] = {}
        live = [(n, p) for n, p in self.peers.items() if p.live(now, self.silence_s)]
        for sysid in sorted(self.cold):
            source = owner(self.prefix, sysid, [n for n, p in live if sysid in p.warm])
            if source is not None:
                plan[sysid] = source
                continue
            knowing = [n for n, p in live if sysid in p.cold]
            if owner(self.prefix, sysid, [*knowing, self.member]) == self.member:
                self.adopted(sysid)
        return plan

    def adopted(self, sysid: int, k: int | None = None, state: Any = None) -> None:
        """The vehicle's estimator is in step with the group again: its state copied (at ``k``: the steps remembered
        before it are not this state's), or nobody else has one."""
        if state is not None and k is not None:
            self.steps[sysid] = deque([(k, state_digest(state))], maxlen=HISTORY)
        self.cold.discard(sysid)
        if sysid not in self.warm:
            self.warm.add(sysid)
            self._version += 1

    def beat_payload(self, now: float) -> dict[str, Any]:
        """What this member's beat says: its warm and cold vehicles and, for those it answers, its last step."""
        steps = {
            str(sysid): list(history[-1])
            for sysid, history in self.steps.items()
            if history and sysid in self.warm and self.owner_of(sysid, now) == self.member
        }
        return {"warm": sorted(self.warm), "cold": sorted(self.cold), "steps": steps}
