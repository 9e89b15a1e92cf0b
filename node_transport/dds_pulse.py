"""Liveliness that comes back: every DDS transport's participant pulses, and a publisher counts as
live while its process pulses.

Why not Cyclone's writer liveliness alone: a remote writer whose automatic lease lapsed once is
"not alive" in Cyclone until *that writer* writes data again (``handle_regular`` is the only place
that sets a proxy writer alive; the participant's liveliness messages renew only writers still
alive).  Cyclone renews a 1 s automatic lease at 80 % of it, so 0.2 s of scheduling delay on a
busy host -- or a process stopped for a moment -- was enough: an idle writer (the result writer of
a machine between runs, the machine of a group the application does not use) then stayed "matched
but not alive" for good, and every reader made afterwards in that process saw it so.  The engine's
link check failed until its timeout, run after run (issue 22).

So each :class:`~node_transport.dds.DdsTransport` writes a small sample (its participant's GUID) on
:data:`TOPIC` every quarter lease from its waiter thread (Python's, not the loop's: a loop busy for a
moment is not a dead process), and hears everybody else's.  A matched publisher of a participant
that pulses is live while that participant pulsed within the publisher's own lease: a process
killed or cut off drops out within its lease as before, and one that pulses again is live again at
once.  A publisher of a participant that does not pulse (a ROS 2 node on rmw_cyclonedds_cpp, a ROS
2 tool) is judged by Cyclone's liveliness as before, and so is one whose process holds its GIL for a
while (no pulse, but Cyclone's threads renew its leases): the count is never below Cyclone's.  The topic has no ``rt/`` prefix, so ROS 2
tools do not list it.
"""
from __future__ import annotations

import time
from typing import Any, Protocol

from node_transport import dds_graph as graph
from node_transport.dds_entities import Taker, matched_handles, write
from node_transport.qos import Durability, History, QoS, Reliability

TOPIC = "dual_arm_executive_liveliness"
TYPE = "rmw_dds_common/msg/Gid"  # 16 octets: the pulsing participant's GUID
BEATS_PER_LEASE = 4  # a lapse needs a whole lease of silence: four beats missed, not one late
FORGET_AFTER = 60.0  # wall seconds after which a silent participant's entry is dropped (bounded memory)
#: best effort, newest only per reader: a lost pulse is replaced by the next one
QOS = QoS(Reliability.BEST_EFFORT, Durability.VOLATILE, History.KEEP_LAST, 64)
INFINITE = float("inf")


class PulsingTransport(Protocol):
    """What :class:`Pulse` needs of dds.py's DdsTransport."""

    dds: Any
    participant: Any
    registry: Any

    def topic(self, name: str, wire_type: type) -> Any: ...

    def type_hash(self, ros_type: str) -> bytes: ...

    def reject(self, topic: str, why: str) -> None: ...


class Pulse:
    """This participant's pulse, and when every other participant last pulsed (``heard``)."""

    def __init__(self, transport: PulsingTransport, lease: float) -> None:
        dds = transport.dds
        self.period = lease / BEATS_PER_LEASE
        wire_type = transport.registry.message(TYPE)
        topic = transport.topic(TOPIC, wire_type)
        qos = graph.dds_qos(QOS, user_data=transport.type_hash(TYPE))
        self.writer = dds.pub.DataWriter(transport.participant, topic, qos=qos)
        self.reader = dds.sub.DataReader(transport.participant, topic, qos=qos)
        self._sample = wire_type(data=list(transport.participant.guid.bytes))
        self._own = transport.participant.guid.bytes
        self._taker = Taker(transport, TOPIC)
        self._next = 0.0
        #: participant GUID (16 bytes) -> time.monotonic() of its last pulse heard
        self.heard: dict[bytes, float] = {}

    def beat(self) -> float:
        """The waiter's thread, whenever it wakes: pulse if due; seconds until the next is due."""
        now = time.monotonic()
        if now >= self._next:
            self._next = now + self.period
            write(self.writer, self._sample)
        return self._next - now

    def on_data(self) -> None:
        """The waiter's thread: note who pulsed (a pulse is its arrival, its content only names the sender)."""
        now = time.monotonic()
        for sample in self._taker.take(self.reader):
            guid = bytes(sample.data)[:16]
            if guid != self._own:
                self.heard[guid] = now
        if len(self.heard) > 64:  # only this thread writes; the loop's thread reads single entries
            for guid, when in list(self.heard.items()):
                if now - when > FORGET_AFTER:
                    self.heard.pop(guid, None)


class LiveCount:
    """A reader's live publishers: pulsing participants' by their pulse, the others' by Cyclone."""

    def __init__(self, reader: Any, pulse: Pulse) -> None:
        self.reader = reader
        self.pulse = pulse
        self._writers: dict[int, tuple[bytes, float]] = {}  # publication handle -> (participant GUID, lease s)
        self._matched: tuple[int, int] | None = None  # Cyclone's (total, current) match counts when _handles was listed
        self._handles: list[int] = []

    def _writer(self, handle: int) -> tuple[bytes, float] | None:
        known = self._writers.get(handle)
        if known is None:
            data = self.reader.get_matched_publication_data(handle)
            if data is None:
                return None
            known = self._writers[handle] = (data.participant_key.bytes, lease_of(data.qos))
            if len(self._writers) > 4096:  # handles of writers long gone
                self._writers = {handle: known}
        return known

    def handles(self) -> list[int]:
        """The matched publications, listed again only when Cyclone's match counts changed (a new
        match raises the total, a lost one lowers the current count): asking the counts costs a
        tenth of listing the handles, and a machine asks before every command."""
        status = self.reader.get_subscription_matched_status()
        matched = (int(status.total_count), int(status.current_count))
        if matched != self._matched:
            self._handles = matched_handles(self.reader, subscriptions=False)
            self._matched = matched
        return self._handles

    def count(self) -> int:
        now = time.monotonic()
        heard = self.pulse.heard
        live = others = 0
        handles = self.handles()
        for handle in handles:
            writer = self._writer(handle)
            if writer is None:
                continue
            participant, lease = writer
            last = heard.get(participant)
            if last is None:
                others += 1
            elif now - last <= lease:
                live += 1
        if live == len(handles):  # every matched publisher pulses: Cyclone cannot count more alive
            return live
        alive = int(self.reader.get_liveliness_changed_status().alive_count)
        if others:  # Cyclone cannot say which writers are alive, only how many: never more than are matched
            live += min(others, alive)
        # a peer whose Python is held up (a long call holding the GIL) does not pulse, but Cyclone's own
        # threads still renew its writers' leases: what Cyclone counts alive is alive
        return max(live, alive)


def lease_of(qos: Any) -> float:
    """The liveliness lease (seconds) a matched writer offers; infinite when it offers none."""
    from cyclonedds.qos import Policy  # optional: pip extra 'dds', only when a DDS transport runs

    try:
        lease = qos[Policy.Liveliness].lease_duration
    except (KeyError, TypeError, AttributeError):
        return INFINITE
    if lease is None or lease < 0 or lease >= 0x7FFFFFFFFFFFFFFF:
        return INFINITE
    return lease / 1e9
