"""A ROS 2 tool started after a DDS-transport cell finds it, with nothing configured on its side.

rmw_cyclonedds_cpp of Jazzy runs Cyclone DDS 0.10.5; on ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
it announces its participant (SPDP) to 127.0.0.1 only, which arrives on the loopback interface.
The transport runs Cyclone 11 from PyPI, which drops SPDP arriving on an interface it does not use
and by itself uses only the host's network interface: a late ``ros2 node list`` saw nothing.  The
late joiner here is that rmw: another process, rmw's XML for LOCALHOST verbatim, and
``AddLocalhost="false"`` so that Cyclone 11 too announces to 127.0.0.1 alone, as 0.10.5 does.
Every wait is bounded; the domain id is the test's own (dds_domain.py); nothing leaves the host.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from node_transport import dds_graph
from node_transport.port import TransportError

ROOT = Path(__file__).resolve().parent.parent
BOUND = 10.0  # seconds the late joiner may take to find the cell on a loaded machine
#: rmw_cyclonedds_cpp's configuration for LOCALHOST (rmw_node.cpp), as Cyclone 0.10.5 carries it out
RMW_LOCALHOST = (
    "<CycloneDDS><Domain><General><AllowMulticast>false</AllowMulticast></General>"
    "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>"
    '<Peers AddLocalhost="false"><Peer address="localhost"/></Peers></Discovery></Domain></CycloneDDS>'
)

CELL = """
import asyncio, sys
from node_transport.clock import real_clock, run_with_clock
from node_transport.dds import DdsTransport
from node_transport.msgs import String
from node_transport.qos import COMMANDS

async def main(clock):
    transport = DdsTransport(clock)
    node = transport.create_node("cell_engine")
    heard = asyncio.Event()
    node.create_subscription(String, "operator_note", lambda m: heard.set(), COMMANDS)
    print("ready", flush=True)
    try:
        await asyncio.wait_for(heard.wait(), float(sys.argv[1]))
        print("heard the late joiner", flush=True)
    except asyncio.TimeoutError:
        print("never heard the late joiner", flush=True)
    await transport.shutdown()

run_with_clock(main, real_clock())
"""

LATE_JOINER = """
import sys, time
from cyclonedds.domain import Domain, DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from node_transport import dds_graph
from node_transport.idl import InterfaceRegistry
from node_transport.qos import COMMANDS

domain_id, config, bound = int(sys.argv[1]), sys.argv[2], float(sys.argv[3])
domain = Domain(domain_id, config)  # kept: the participant joins this configured domain
participant = DomainParticipant(domain_id)
registry = InterfaceRegistry()
info = registry.message(dds_graph.DISCOVERY_TYPE)
graph = DataReader(participant, Topic(participant, dds_graph.DISCOVERY_TOPIC, info), qos=dds_graph.dds_qos(dds_graph.DISCOVERY_READER))
note_type = registry.message("std_msgs/msg/String")
note = DataWriter(participant, Topic(participant, "rt/operator_note", note_type), qos=dds_graph.dds_qos(COMMANDS))
deadline, names = time.monotonic() + bound, set()
while time.monotonic() < deadline and "cell_engine" not in names:
    for sample in graph.take(N=64):
        names.update(str(n.node_name) for n in sample.node_entities_info_seq)
    time.sleep(0.05)
print("nodes:", ",".join(sorted(names)), flush=True)
for _ in range(int(2 * bound / 0.1)):  # until the test ends it: the cell hears it once its reader has matched
    note.write(note_type(data="late joiner here"))
    time.sleep(0.1)
"""


def _environment(extra: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("ROS_", "CYCLONEDDS"))}
    return {**env, **extra, "PYTHONPATH": str(ROOT)}


def test_a_ros_tool_started_after_a_localhost_cell_finds_it_and_is_found(dds_env: dict[str, str]) -> None:
    domain = int(dds_env["ROS_DOMAIN_ID"])  # a domain of its own (dds_domain.py); the rest of dds_env is what this test varies
    cell_env = _environment({"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    cell = subprocess.Popen([sys.executable, "-c", CELL, str(2 * BOUND)], cwd=ROOT, env=cell_env, stdout=subprocess.PIPE, text=True)
    joiner = None
    try:
        assert cell.stdout is not None and cell.stdout.readline().strip() == "ready"
        joiner = subprocess.Popen(
            [sys.executable, "-c", LATE_JOINER, str(domain), RMW_LOCALHOST, str(BOUND)],
            cwd=ROOT, env=_environment({}), stdout=subprocess.PIPE, text=True,
        )
        assert joiner.stdout is not None
        seen = joiner.stdout.readline()  # within BOUND: the joiner gives up looking by then
        heard = cell.communicate(timeout=3 * BOUND)[0]  # the cell ends once it heard, or after 2 * BOUND
    finally:
        for child in (cell, joiner):
            if child is not None:
                child.kill()
                child.communicate(timeout=BOUND)
    assert "cell_engine" in seen.split("nodes:")[-1].strip().split(","), seen  # ros2 node list's source
    assert heard.strip() == "heard the late joiner"  # and the cell's reader matched the tool's writer


# ------------------------------------------------------------------ the configuration, as rmw and rcl make it
LO = '<NetworkInterface address="127.0.0.1"/>'


def test_localhost_uses_the_loopback_interface_with_rmws_discovery_settings() -> None:
    local = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"})
    assert local is not None
    assert f"<Interfaces>{LO}</Interfaces>" in local and "autodetermine" not in local
    assert "<AllowMulticast>false</AllowMulticast>" in local and '<Peer address="localhost"/>' in local
    assert "<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>32</MaxAutoParticipantIndex>" in local
    on_host = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_STATIC_PEERS": "127.0.0.1;::1;localhost"})
    assert on_host is not None and f"<Interfaces>{LO}</Interfaces>" in on_host


def test_localhost_with_peers_elsewhere_keeps_the_network_interface_beside_the_loopback() -> None:
    config = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_STATIC_PEERS": "10.0.0.2;cellpc"})
    assert config is not None
    assert f'<Interfaces><NetworkInterface autodetermine="true"/>{LO}</Interfaces>' in config
    assert '<Peer address="localhost"/><Peer address="10.0.0.2"/><Peer address="cellpc"/>' in config


@pytest.mark.parametrize("range_", ["", "SUBNET", "SYSTEM_DEFAULT", "OFF"])
def test_other_ranges_leave_the_interfaces_to_cyclone(range_: str) -> None:
    config = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": range_, "ROS_STATIC_PEERS": "127.0.0.1"})
    assert config is None or "Interfaces" not in config
    if range_ == "SYSTEM_DEFAULT":
        assert config is None  # rmw changes nothing, static peers ignored


def test_a_users_cyclonedds_uri_that_names_interfaces_decides_them(tmp_path: Path) -> None:
    mine = '<CycloneDDS><Domain><General><Interfaces><NetworkInterface name="eth1"/></Interfaces></General></Domain></CycloneDDS>'
    inline = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "CYCLONEDDS_URI": mine})
    assert inline is not None and inline.count("NetworkInterface") == 1 and inline.endswith("," + mine)
    file = tmp_path / "cyclone.xml"
    file.write_text(mine, encoding="utf-8")
    for uri in (f"file://{file}", str(file), str(tmp_path / "missing.xml")):
        config = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "CYCLONEDDS_URI": uri})
        assert config is not None and "<Interfaces>" not in config and config.endswith("," + uri)
    tracing = '<CycloneDDS><Domain><Tracing><Verbosity>warning</Verbosity></Tracing></Domain></CycloneDDS>'
    config = dds_graph.domain_config({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "CYCLONEDDS_URI": tracing})
    assert config is not None and LO in config  # a URI that does not name interfaces keeps the fix


def test_ros_localhost_only_is_honoured_as_rcl_does(caplog: pytest.LogCaptureFixture) -> None:
    only = dds_graph.discovery_options({"ROS_LOCALHOST_ONLY": "1", "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "ROS_STATIC_PEERS": "10.0.0.2"})
    assert only == dds_graph.DiscoveryOptions("LOCALHOST", ())
    assert "ROS_LOCALHOST_ONLY is deprecated" in caplog.text
    assert dds_graph.discovery_options({"ROS_LOCALHOST_ONLY": "0"}) == dds_graph.DiscoveryOptions("SUBNET", ())
    assert dds_graph.discovery_options({"ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF", "ROS_STATIC_PEERS": "10.0.0.2"}).static_peers == ()


def test_static_peers_are_read_as_rcl_reads_them(caplog: pytest.LogCaptureFixture) -> None:
    long = "a" * 300
    assert dds_graph.discovery_options({"ROS_STATIC_PEERS": f";10.0.0.2; ;{long};cellpc;"}).static_peers == ("10.0.0.2", "cellpc")
    assert "longer than 255" in caplog.text
    with pytest.raises(TransportError, match="not a host name"):
        dds_graph.discovery_options({"ROS_STATIC_PEERS": '"/><Evil'})
    with pytest.raises(TransportError, match="use one of"):
        dds_graph.discovery_options({"ROS_AUTOMATIC_DISCOVERY_RANGE": "everywhere"})
    assert [p for p in ("localhost", "127.0.0.5", "::1", "[::1]", "10.0.0.2", "cellpc", "localhostx") if dds_graph.is_loopback(p)] == [
        "localhost", "127.0.0.5", "::1", "[::1]"]


@pytest.mark.parametrize("extra", [
    {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"},
    {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "ROS_STATIC_PEERS": "192.0.2.77"},
    {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
     "CYCLONEDDS_URI": '<CycloneDDS><Domain><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces></General></Domain></CycloneDDS>'},
    {"ROS_LOCALHOST_ONLY": "1"},
])
def test_cyclone_accepts_every_configuration_made(extra: dict[str, str], dds_env: dict[str, str]) -> None:
    """Cyclone refuses e.g. an interface named twice; each configuration here makes a participant (the
    remote static peer is left out of the probe: a participant announces itself to its peers at once)."""
    probe = (
        "import sys\nfrom cyclonedds.domain import Domain, DomainParticipant\n"
        "d = Domain(int(sys.argv[1]), sys.argv[2]); DomainParticipant(int(sys.argv[1])); print('ok')"
    )
    domain = dds_env["ROS_DOMAIN_ID"]
    config = dds_graph.domain_config(extra)
    assert config is not None
    config = config.replace('<Peer address="192.0.2.77"/>', "")  # what is checked is the interfaces; nothing goes off the host
    done = subprocess.run([sys.executable, "-c", probe, domain, config], env=_environment({}), capture_output=True, text=True, timeout=BOUND)
    assert done.stdout.strip() == "ok", done.stderr
