"""Small helpers over cyclonedds entities for :mod:`node_transport.dds`.

Taking samples in batches and decoding them one at a time (a bad one costs only itself), writing a
sample encoded by the compiled codec (:mod:`~node_transport.dds_cdr`), listing matched endpoints without
cyclonedds-python's race, deleting an entity now, and telling who called a service.
"""
from __future__ import annotations

import ctypes
from dataclasses import dataclass
from typing import Any, Protocol

from node_transport import dds_graph as graph
from node_transport.dds_cdr import codec
from node_transport.port import TransportError

TAKE_LIMIT = 10_000  # samples taken in one handler call; the rest wait for the next
BATCH = 64  # samples taken per call into Cyclone
FAILURE_LIMIT = 1000  # undecodable samples in a row before a handler call gives up until the next


_LOADED: list[tuple[Any, int]] = []


def _clayer() -> tuple[Any, int]:
    """cyclonedds-python's C layer and the mask of every sample a reader holds, looked up once (an
    import statement in a function costs 2 us a call, the mask's three flags another few)."""
    if not _LOADED:
        from cyclonedds import _clayer as clayer, core  # optional: pip extra 'dds'; only a DDS transport reads or writes

        _LOADED.append((clayer, int(core.SampleState.Any | core.ViewState.Any | core.InstanceState.Any)))
    return _LOADED[0]


def delete(entity: Any) -> None:
    """Delete a Cyclone entity now (a take under way on another thread finishes first)."""
    try:
        entity.__del__()
    except Exception:  # noqa: BLE001 - an entity already gone with its parent
        pass


class Rejecting(Protocol):
    """What a :class:`Taker` needs of its transport (dds.py's DdsTransport): the cyclonedds modules, and
    where a sample that does not decode is counted and told."""

    @property
    def dds(self) -> Any: ...

    def reject(self, topic: str, why: str) -> None: ...


class Taker:
    """Takes what a reader holds, up to :data:`BATCH` samples per call into Cyclone, and decodes them
    one by one, so a bad one costs only itself (on the waiter's thread or the loop)."""

    def __init__(self, transport: Rejecting, topic: str) -> None:
        self.transport = transport
        self.topic = topic

    def take(self, reader: Any) -> list[Any]:
        clayer, mask = _clayer()
        ddspy_take = clayer.ddspy_take
        decode = codec(reader.topic.data_type).decode
        samples: list[Any] = []
        failures = taken = 0
        while taken < TAKE_LIMIT:
            try:
                got = ddspy_take(reader._ref, mask, BATCH)
            except Exception:  # noqa: BLE001 - a reader deleted under the call
                break
            if isinstance(got, int):
                break  # an error code: the reader is being deleted
            taken += len(got)
            for data, info in got:
                if not info.valid_data:
                    continue  # a writer gone or an instance disposed: no sample
                try:
                    sample = decode(data)
                except Exception as error:  # noqa: BLE001 - undecodable CDR (taken, so gone): count it, keep going
                    self.transport.reject(self.topic, f"undecodable sample: {type(error).__name__}: {error}")
                    failures += 1
                    continue
                sample.sample_info = info
                samples.append(sample)
            if len(got) < BATCH or failures >= FAILURE_LIMIT:
                break
        return samples


def write(writer: Any, sample: Any) -> None:
    """Write ``sample`` (an instance of the writer's wire type) with the compiled codec: the bytes
    cyclonedds-python's ``DataWriter.write`` would write, in a fraction of its time."""
    ret = _clayer()[0].ddspy_write(writer._ref, codec(type(sample)).encode(sample))
    if ret < 0:
        from cyclonedds.core import DDSException  # optional: pip extra 'dds'

        raise DDSException(ret, f"Occurred while writing sample in {writer!r}")


@dataclass(frozen=True)
class Caller:
    """Who sent a request, as its request writer's discovery data tells: the reply goes to this
    caller's reply reader.  An rmw client names that reader in ``clientid=`` user data; a client
    without it (ros2-client on RustDDS, or any plain DDS peer using rmw_cyclonedds_cpp's header)
    is known only by its participant, so any reply reader of that participant will do."""

    client_id: str | None
    participant: Any  # the request writer's participant key (a UUID), None when unknown

    @classmethod
    def of(cls, publication: Any) -> Caller:
        if publication is None:
            return cls(None, None)
        return cls(graph.user_data_value(publication.qos, "clientid"), getattr(publication, "participant_key", None))

    def reads(self, subscription: Any) -> bool:
        """Whether a matched reply reader is this caller's."""
        if self.client_id is not None:
            return graph.user_data_value(subscription.qos, "clientid") == self.client_id
        return self.participant is not None and getattr(subscription, "participant_key", None) == self.participant


def matched_handles(entity: Any, *, subscriptions: bool) -> list[int]:
    """Instance handles of what a writer's readers (``subscriptions``) or a reader's writers are.

    cyclonedds-python's ``get_matched_subscriptions``/``get_matched_publications`` size their buffer
    with a first call and index it with the count of a second one: a peer matched in between is an
    IndexError in the caller.  Here the count Cyclone answers is checked against the room given,
    and asked again with more room.
    """
    from cyclonedds.internal import dds_c_t  # optional: pip extra 'dds'; only a DDS transport has entities

    call = entity._get_matched_subscriptions if subscriptions else entity._get_matched_publications
    room = 16
    for _ in range(8):
        buffer = (dds_c_t.instance_handle * room)()
        count = int(call(entity._ref, ctypes.cast(buffer, ctypes.POINTER(dds_c_t.instance_handle)), room))
        if count < 0:
            raise TransportError(f"cannot list the matched endpoints of a DDS entity (DDS return code {count})")
        if count <= room:
            return [int(h) for h in buffer[:count]]
        room = count + 16
    return [int(h) for h in buffer[:room]]  # still growing: what fitted


def matched(entity: Any, *, subscriptions: bool) -> list[Any]:
    handles = matched_handles(entity, subscriptions=subscriptions)
    getter = entity.get_matched_subscription_data if subscriptions else entity.get_matched_publication_data
    found = []
    for handle in handles:
        data = getter(handle)
        if data is not None:
            found.append(data)
    return found
