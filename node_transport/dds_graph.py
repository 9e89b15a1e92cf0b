"""What makes plain DDS a ROS 2 graph: names, QoS, domain configuration, ``ros_discovery_info``.

Pure data and small helpers for :mod:`node_transport.dds`, each matching what
``rmw_cyclonedds_cpp`` (ROS 2 Jazzy) does, so that ROS 2 tools see our nodes as their own:

* topic names: ``rt/<topic>``, services ``rq/<service>Request`` and ``rr/<service>Reply``;
* QoS: reliability, durability (with Cyclone's durability service for transient local), history,
  no autodispose, plain CDR (XCDR1), ``serviceid=``/``clientid=`` user data pairing a service's
  request reader with its reply writer;
* the domain: ``ROS_DOMAIN_ID`` (0..232), ``ROS_AUTOMATIC_DISCOVERY_RANGE`` (SUBNET, LOCALHOST,
  OFF, SYSTEM_DEFAULT), ``ROS_STATIC_PEERS`` (``;``-separated), the deprecated
  ``ROS_LOCALHOST_ONLY``, then ``CYCLONEDDS_URI`` appended as rmw does, so a Cyclone
  configuration for networks without multicast applies unchanged; on LOCALHOST the loopback
  interface, so rmw_cyclonedds_cpp's Cyclone 0.10 finds us (see :func:`domain_config`);
* node discovery: ``rmw_dds_common/msg/ParticipantEntitiesInfo`` on ``ros_discovery_info``, GIDs
  the 16-byte DDS GUIDs of the participant and of every reader and writer of each node.
"""
from __future__ import annotations

import ipaddress
import logging
import os
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from node_transport.port import TransportError
from node_transport.qos import Durability, History, QoS, Reliability

log = logging.getLogger(__name__)

MAX_DOMAIN_ID = 232  # rcl's limit for the default port mapping
DISCOVERY_TOPIC = "ros_discovery_info"  # the DDS name itself: rmw publishes it without "rt/"
DISCOVERY_TYPE = "rmw_dds_common/msg/ParticipantEntitiesInfo"
ENCLAVE_USER_DATA = b"enclave=/;"  # what rmw puts in the participant's user data
DISCOVERY_RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")
MAX_PEER_LENGTH = 255  # RMW_DISCOVERY_OPTIONS_STATIC_PEERS_MAX_LENGTH - 1: rcl skips longer peers
MAX_CONFIG_FILE = 1 << 20  # bytes of a CYCLONEDDS_URI file read to see whether it names interfaces
#: rmw_qos_profile_services_default
SERVICES = QoS(Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 10)
#: what rmw publishes ros_discovery_info with
DISCOVERY = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1)
#: how this process reads it, between polls: one topic without keys, so every process's updates share the depth
DISCOVERY_READER = QoS(Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1000)


def topic_name(resolved: str) -> str:
    """``/joint_states`` -> ``rt/joint_states``."""
    return "rt" + resolved


def request_topic(service: str) -> str:
    return f"rq{service}Request"


def reply_topic(service: str) -> str:
    return f"rr{service}Reply"


def domain_id(env: Mapping[str, str] = os.environ) -> int:
    """``ROS_DOMAIN_ID`` (default 0), checked as rcl checks it."""
    text = env.get("ROS_DOMAIN_ID", "").strip()
    if not text:
        return 0
    try:
        value = int(text)
    except ValueError:
        raise TransportError(f"ROS_DOMAIN_ID={text!r} is not an integer") from None
    if not 0 <= value <= MAX_DOMAIN_ID:
        raise TransportError(f"ROS_DOMAIN_ID={value} is outside 0..{MAX_DOMAIN_ID}")
    return value


@dataclass(frozen=True)
class DiscoveryOptions:
    """What rcl makes of the environment for rmw's discovery (rcl/init.c, discovery_options.c)."""

    automatic_range: str  # one of DISCOVERY_RANGES
    static_peers: tuple[str, ...]


def discovery_options(env: Mapping[str, str] = os.environ) -> DiscoveryOptions:
    """``ROS_AUTOMATIC_DISCOVERY_RANGE`` (empty: SUBNET), ``ROS_STATIC_PEERS`` (``;``-separated, not
    read with OFF), and the deprecated ``ROS_LOCALHOST_ONLY=1``, which wins over both as in rcl."""
    if env.get("ROS_LOCALHOST_ONLY", "").startswith("1"):
        log.warning("ROS_LOCALHOST_ONLY is deprecated but still honored: discovery on this host only, "
                    "ROS_AUTOMATIC_DISCOVERY_RANGE and ROS_STATIC_PEERS ignored (use ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST)")
        return DiscoveryOptions("LOCALHOST", ())
    range_ = env.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper() or "SUBNET"
    if range_ not in DISCOVERY_RANGES:
        raise TransportError(f"ROS_AUTOMATIC_DISCOVERY_RANGE={range_!r}: use one of {', '.join(DISCOVERY_RANGES)}")
    if range_ == "OFF":
        return DiscoveryOptions(range_, ())
    peers: list[str] = []
    for peer in (p.strip() for p in env.get("ROS_STATIC_PEERS", "").split(";")):
        if not peer:
            continue
        if any(c in peer for c in "<>\"&'"):
            raise TransportError(f"ROS_STATIC_PEERS: {peer!r} is not a host name or address")
        if len(peer) > MAX_PEER_LENGTH:
            log.warning("ROS_STATIC_PEERS: %s... is longer than %d characters; skipped (as rcl does)", peer[:40], MAX_PEER_LENGTH)
            continue
        peers.append(peer)
    return DiscoveryOptions(range_, tuple(peers))


def is_loopback(peer: str) -> bool:
    """``localhost`` or a loopback address literal (no name is looked up)."""
    if peer.lower() in ("localhost", "localhost.localdomain", "ip6-localhost"):
        return True
    try:
        return ipaddress.ip_address(peer.strip("[]")).is_loopback
    except ValueError:
        return False


def uri_selects_interfaces(uri: str) -> bool:
    """Whether a ``CYCLONEDDS_URI`` (XML fragments and files, comma-separated) names network
    interfaces; one that cannot be read counts as naming them (Cyclone reports it itself)."""
    if "NetworkInterface" in uri:
        return True
    for part in (p.strip() for p in uri.split(",")):
        if not part or "<" in part:
            continue
        path = part[len("file://"):] if part.startswith("file://") else part
        try:
            with open(path, "rb") as stream:
                if b"NetworkInterface" in stream.read(MAX_CONFIG_FILE):
                    return True
        except OSError:
            return True
    return False


def domain_config(env: Mapping[str, str] = os.environ) -> str | None:
    """The Cyclone configuration rmw_cyclonedds_cpp would use, or None for Cyclone's default.

    rmw's XML (rmw_node.cpp, ``check_create_domain``), then ``CYCLONEDDS_URI`` appended, plus one
    thing rmw does not need: the loopback interface when localhost is a discovery peer.  Cyclone
    0.10 (rmw_cyclonedds_cpp of Jazzy) on LOCALHOST sends its participant announcements (SPDP) to
    127.0.0.1 only, which the kernel delivers on the loopback interface; Cyclone 11 (cyclonedds
    from PyPI) drops SPDP that arrives on an interface it does not use, and left to itself it uses
    the host's network interface.  So a ROS 2 tool started after the cell was never answered.
    LOCALHOST with peers all on this host uses the loopback interface only (what LOCALHOST means);
    with peers elsewhere too, the loopback beside the automatically chosen interface.  A
    ``CYCLONEDDS_URI`` that names interfaces itself is left to decide (Cyclone refuses an interface
    named twice).
    """
    options = discovery_options(env)
    range_, peers = options.automatic_range, options.static_peers
    localhost_peer = range_ == "LOCALHOST"
    use_peers = range_ in ("SUBNET", "LOCALHOST")
    no_multicast = range_ in ("LOCALHOST", "OFF")
    uri = env.get("CYCLONEDDS_URI", "").strip()
    parts: list[str] = []
    if localhost_peer or (use_peers and peers) or no_multicast:
        general = ""
        if localhost_peer and not uri_selects_interfaces(uri):
            remote = [p for p in peers if not is_loopback(p)]
            general += "<Interfaces>" + ('<NetworkInterface autodetermine="true"/>' if remote else "")
            general += '<NetworkInterface address="127.0.0.1"/></Interfaces>'
        if no_multicast:
            general += "<AllowMulticast>false</AllowMulticast>"
        xml = "<CycloneDDS><Domain>" + (f"<General>{general}</General>" if general else "")
        if range_ == "OFF":
            xml += f"<Discovery><ParticipantIndex>none</ParticipantIndex><Tag>ros_discovery_off_{os.getpid()}</Tag>"
        else:
            xml += "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
        listed = (["localhost"] if localhost_peer else []) + (list(peers) if use_peers else [])
        if listed:
            xml += "<Peers>" + "".join(f'<Peer address="{p}"/>' for p in listed) + "</Peers>"
        xml += "</Discovery></Domain></CycloneDDS>"
        parts.append(xml)
    if uri:
        parts.append(uri)
    return ",".join(parts) if parts else None


def dds_qos(qos: QoS, *, user_data: bytes = b"", lease: float | None = None) -> Any:
    """The cyclonedds ``Qos`` of a ROS endpoint with ``qos``; ``lease`` (s): automatic liveliness."""
    from cyclonedds.qos import Policy, Qos  # optional: pip extra 'dds', only when a DDS transport runs
    from cyclonedds.util import duration  # optional: pip extra 'dds'

    history = Policy.History.KeepAll if qos.history is History.KEEP_ALL else Policy.History.KeepLast(qos.depth)
    policies: list[Any] = [
        Policy.Reliability.Reliable(max_blocking_time=duration(infinite=True))
        if qos.reliability is Reliability.RELIABLE else Policy.Reliability.BestEffort,
        history,
        Policy.WriterDataLifecycle(autodispose=False),
        Policy.DataRepresentation(use_cdrv0_representation=True),
    ]
    if qos.durability is Durability.TRANSIENT_LOCAL:
        policies.append(Policy.Durability.TransientLocal)
        policies.append(Policy.DurabilityService(
            cleanup_delay=0, history=history, max_samples=-1, max_instances=-1, max_samples_per_instance=-1,
        ))
    else:
        policies.append(Policy.Durability.Volatile)
    if lease is not None:
        policies.append(Policy.Liveliness.Automatic(lease_duration=duration(seconds=lease)))
    if user_data:
        policies.append(Policy.Userdata(data=user_data))
    return Qos(*policies)


def user_data_value(qos: Any, key: str) -> str | None:
    """``key=value;`` from an endpoint's user data (``serviceid``, ``clientid``), or None."""
    from cyclonedds.qos import Policy  # optional: pip extra 'dds', only when a DDS transport runs

    try:
        data = qos[Policy.Userdata].data
    except (KeyError, TypeError, AttributeError):
        return None
    for item in bytes(data).decode("utf-8", "replace").split(";"):
        name, sep, value = item.partition("=")
        if sep and name.strip() == key:
            return value
    return None


def gid(guid_bytes: bytes) -> list[int]:
    """rmw_dds_common/Gid ``data`` (16 octets) of a DDS GUID."""
    data = list(guid_bytes[:16])
    return data + [0] * (16 - len(data))


def discovery_message(
    registry: Any, participant_guid: bytes, nodes: Mapping[tuple[str, str], tuple[list[bytes], list[bytes]]]
) -> Any:
    """The ParticipantEntitiesInfo of this process: each node (namespace, name) with the GUIDs of
    its readers and writers."""
    gid_cls = registry.message("rmw_dds_common/msg/Gid")
    node_cls = registry.message("rmw_dds_common/msg/NodeEntitiesInfo")
    info_cls = registry.message(DISCOVERY_TYPE)
    infos = [
        node_cls(
            node_namespace=namespace, node_name=name,
            reader_gid_seq=[gid_cls(data=gid(g)) for g in readers],
            writer_gid_seq=[gid_cls(data=gid(g)) for g in writers],
        )
        for (namespace, name), (readers, writers) in sorted(nodes.items())
    ]
    return info_cls(gid=gid_cls(data=gid(participant_guid)), node_entities_info_seq=infos)


class WriterOwners:
    """Writer GUID -> the fully qualified name of its node, read from ``ros_discovery_info``.

    Entries outlive their writers (a killed process sends no last update), so a watcher can still
    name the node of a publisher it has lost; the oldest are forgotten past :attr:`LIMIT`.
    """

    LIMIT = 10_000

    def __init__(self) -> None:
        self._names: OrderedDict[bytes, str] = OrderedDict()

    def update(self, info: Any) -> None:
        """Take one ParticipantEntitiesInfo sample."""
        found: list[tuple[bytes, str]] = []
        for node in info.node_entities_info_seq:
            namespace = str(node.node_namespace)
            fqn = f"{namespace.rstrip('/')}/{node.node_name}"
            found.extend((bytes(g.data)[:16], fqn) for g in node.writer_gid_seq)
        for guid, fqn in found:
            self._names.pop(guid, None)
            self._names[guid] = fqn
        while len(self._names) > self.LIMIT:
            self._names.popitem(last=False)

    def __contains__(self, guid: object) -> bool:
        return guid in self._names

    def __getitem__(self, guid: bytes) -> str:
        return self._names[guid]
