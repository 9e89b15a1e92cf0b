"""The ``vplus_bridge`` entry point's parameters become back-end options (ROS 2 itself: test_ros_*)."""
from __future__ import annotations

from typing import Any

import pytest

from cell_runner.bridge_nodes.vplus import BACKEND, declare_vplus_parameters
from node_transport.clock import Clock
from node_transport.local import LocalTransport
from node_transport.port import TransportError
from robot_bridges.registry import create_backend


def test_defaults_start_the_simulator_and_overrides_reach_the_backend(run_sim: Any) -> None:
    async def main(clock: Clock) -> None:
        bus = LocalTransport(clock)
        setup = declare_vplus_parameters(bus.create_node("vplus_bridge"))
        assert setup.options.host is None and setup.options.port == 1234 and setup.speed == 1.0
        custom = declare_vplus_parameters(
            bus.create_node("real", parameters={"host": "192.168.0.10", "port": 2000, "timeout": 9.5, "linear": "reject", "tolerance_mm": 2.5})
        )
        assert (custom.options.host, custom.options.port) == ("192.168.0.10", 2000)
        assert custom.options.extra == {"timeout": "9.5", "retries": "3", "linear": "reject", "tolerance_mm": "2.5", "tolerance_deg": "0.5"}
        backend = await create_backend(BACKEND, clock, setup.options.__class__(robot=setup.options.robot, extra=setup.options.extra))
        await backend.close()
        with pytest.raises(TransportError, match=r"^/bad: parameter 'port' must be a whole number in \[0, 65535\], got 70000$"):
            declare_vplus_parameters(bus.create_node("bad", parameters={"port": 70000}))
        with pytest.raises(TransportError, match="must be an integer, got string"):
            declare_vplus_parameters(bus.create_node("typed", parameters={"port": "1234"}))

    run_sim(main)
