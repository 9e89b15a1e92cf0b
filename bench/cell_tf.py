"""The bridges' state tick in a cell of several robots, with each robot drawn (its URDF and tf) and without.

Usage: python bench/cell_tf.py [--ticks N]

Since c463189 every robot of a cell publishes its placed URDF and, while someone listens to ``/tf`` (RViz,
Foxglove), its links with every joint state -- before, a placed robot published neither.  This measures what that
costs per state period (``BridgeNode.publish_state``: joint_states, tf, tcp_pose), side by side: a Viper and a
Nextage placed in one cell, each on its simulator and its own bridge on one local transport, drawn (as now) and
undrawn (a back end without a URDF, as a placed robot was), idle (the robots at rest: a joint at rest keeps its
transform, no kinematics) and moving (every joint a little further each tick: the forward kinematics each tick),
without and with a ``/tf`` listener.  CPU per tick of both bridges, median of 5 rounds.  Last line: one JSON object.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core_functions.cell_robots import CellNames  # noqa: E402
from core_functions.geometry import Pose  # noqa: E402
from core_functions.robots import ADEPT_VIPER_S850, NEXTAGE_OPEN  # noqa: E402
from node_transport.clock import Clock, run_with_clock, simulated_clock  # noqa: E402
from node_transport.local import LocalTransport  # noqa: E402
from node_transport.msgs import TFMessage  # noqa: E402
from node_transport.qos import TF  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from robot_bridges.bridge_node import BridgeNode  # noqa: E402
from robot_bridges.placed import PlacedBackend  # noqa: E402
from robot_bridges.registry import create_backend  # noqa: E402


class Undrawn(PlacedBackend):
    """A placed robot as before c463189: no URDF, so its bridge publishes neither robot_description nor tf."""

    def robot_description(self) -> str | None:
        return None


class Moving(PlacedBackend):
    """Every joint a little further at each joint state: the links' transforms change each tick."""

    step = 0

    def joint_state(self) -> tuple[tuple[str, ...], tuple[float, ...]]:
        names, positions = super().joint_state()
        self.step += 1
        return names, tuple(p + 1e-4 * (self.step % 100) for p in positions)


async def measure(clock: Clock, drawn: bool, moving: bool, listened: bool, ticks: int) -> float:
    """CPU seconds per tick of both bridges."""
    kind = (Moving if moving else PlacedBackend) if drawn else Undrawn
    viper = kind(await create_backend("vplus", clock, BackendOptions(robot=ADEPT_VIPER_S850)), Pose.from_xyz_rpy(1.5, 0, 0, 0, 0, 3.14159), "checker", CellNames("viper_"))
    nextage = kind(await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN)), Pose(), "assembler")
    bus = LocalTransport(clock)
    if listened:
        bus.create_node("rviz").create_subscription(TFMessage, "/tf", lambda _m: None, TF)
    bridges = [BridgeNode(bus.create_node(f"{n}_bridge"), b) for n, b in (("checker", viper), ("assembler", nextage))]
    for bridge in bridges:
        await bridge.start()
    try:
        for bridge in bridges:
            bridge.publish_state()  # the first: tf_static, the URDF's cache
        start = time.process_time()
        for _ in range(ticks):
            for bridge in bridges:
                bridge.publish_state()
        return (time.process_time() - start) / ticks
    finally:
        for bridge in bridges:
            await bridge.close()
        await viper.close()
        await nextage.close()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=2000)
    ticks = parser.parse_args().ticks
    results: dict[str, float] = {}
    for drawn in (False, True):
        for moving in (False, True):
            for listened in (False, True):
                if moving and not drawn:
                    continue  # undrawn: nothing depends on the joints but joint_states
                label = f"{'drawn' if drawn else 'undrawn'} {'moving' if moving else 'idle'} {'tf listener' if listened else 'no listener'}"
                rounds = [run_with_clock(lambda c: measure(c, drawn, moving, listened, ticks), simulated_clock()) for _ in range(5)]
                results[label] = statistics.median(rounds) * 1e6
                print(f"{label:40s} {results[label]:8.1f} us CPU per tick (both bridges)")
    print(json.dumps({"bench": "cell_tf", "ticks": ticks, "us_cpu_per_tick": results}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
