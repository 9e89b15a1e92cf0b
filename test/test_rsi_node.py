"""The ``kuka_rsi_bridge`` entry point's parameters become back-end options (ROS 2 itself: test_ros_*)."""
from __future__ import annotations

from typing import Any

import pytest

from execution_engine.clock import Clock
from execution_engine.transport.local import LocalTransport
from execution_engine.transport.port import TransportError
from robot_bridges.kuka_rsi.node import declare_kuka_parameters


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
