"""The ``kuka_rsi_bridge`` entry point's parameters become back-end options (ROS 2 itself: test_ros_*)."""
from __future__ import annotations

from typing import Any

import pytest

from cell_runner.bridge_nodes.kuka_rsi import declare_kuka_parameters
from node_transport.clock import Clock, real_clock, run_with_clock
from node_transport.local import LocalTransport
from node_transport.port import TransportError
from robot_bridges.backend import BackendOptions
from robot_bridges.kuka_rsi.backend import KukaRsiBackend, create


def test_defaults_start_the_simulator_and_a_real_controller_is_named(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        bus = LocalTransport(clock)
        simulated = declare_kuka_parameters(bus.create_node("kuka_rsi_bridge")).options
        assert simulated.rsi_listen is None and simulated.host is None
        assert simulated.extra["cycle"] == "4" and simulated.extra["runner"] == "process" and "config" not in simulated.extra
        assert "silence" not in simulated.extra  # the back end chooses (an accelerated simulator needs longer)
        real = declare_kuka_parameters(bus.create_node("real", parameters={"rsi_listen": "192.168.1.10:49152", "host": "192.168.1.20", "cycle": 12})).options
        assert (real.rsi_listen, real.host, real.extra["cycle"]) == ("192.168.1.10:49152", "192.168.1.20", "12")
        with pytest.raises(TransportError, match="must be an integer, got string"):
            declare_kuka_parameters(bus.create_node("typed", parameters={"cycle": "4"}))

    run_sim(main)


def test_the_trust_and_start_up_options_are_node_parameters(run_sim: Any) -> None:
    """What a ROS user of a real controller must be able to set: the cross-check's tolerances, the
    wait for the first packet, and the port the controller sends from."""
    async def declare(clock: Clock) -> BackendOptions:
        bus = LocalTransport(clock)
        defaults = declare_kuka_parameters(bus.create_node("kuka_rsi_bridge")).options
        assert (defaults.extra["tolerance"], defaults.extra["tolerance_mm"], defaults.extra["connect_timeout"]) == ("0.1", "1.0", "10.0")
        assert defaults.port is None
        with pytest.raises(TransportError, match="port"):
            declare_kuka_parameters(bus.create_node("typed", parameters={"port": "6008"}))
        parameters = {"rsi_listen": "127.0.0.1:0", "host": "localhost", "port": 6008, "tolerance": 0.05, "tolerance_mm": 0.5, "connect_timeout": 3.0}
        return declare_kuka_parameters(bus.create_node("real", parameters=parameters)).options

    options = run_sim(declare)

    async def build(clock: Clock) -> KukaRsiBackend:
        return await create(clock, options)

    backend = run_with_clock(build, real_clock())  # built, not started: nothing is bound
    link, settings = backend.link, backend.settings
    assert (link.host, link.port, link.setpoint_tolerance_deg, link.tcp_tolerance_mm) == ("127.0.0.1", 6008, (0.05,) * 6, 0.5)
    assert settings.connect_timeout == 3.0
