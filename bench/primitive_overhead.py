"""Overhead per primitive: engine + group machine + transport + bridge node, vs calling the back end directly.

Both sides execute the same primitives on the same Nextage simulator back end, in one process and one run, on
real (wall) time:

* direct:   ``await backend.execute("left_arm", SetSpeed(f))`` N times;
* function: an application of N operations, each one ``set_speed`` on left_arm (one primitive per function, so the
            engine's dispatch, result and Ready check are paid for every primitive: the worst case);
* skill:    one operation whose function yields N primitives (what a real skill does: the machine and transport
            are paid per primitive, the engine once).

``set_speed`` does no motion, so the direct figure is the back end's own cost and the differences are pure
orchestration overhead.

The peer, measured in the same rounds, interleaved: one tick of a py_trees behaviour tree (a sequence over
one behaviour that sets the same speed fraction) -- the cost of one step of a mature Python executive.
Issue 22 asks for a primitive within 10 transitions of a SMACH state machine (executive_smach, which is not
on PyPI); the issue's own side-by-side figures put one py_trees tick at about 2.3 SMACH transitions (a
primitive was 46-52x a transition and 20-22x a tick in the same runs), so the aim reads as about 4.3 ticks
per primitive.  py_trees comes from the bench's own requirements (``pip install -r bench/requirements.txt``);
nothing is fetched at run time, and without it the bench says so and prints no factor.

Run:  python bench/primitive_overhead.py [N] [ROUNDS]   (N primitives per round, in 4 chunks; 3 rounds)
"""
from __future__ import annotations

import asyncio
import json
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app_functions.registry import LIBRARIES  # noqa: E402
from cell_runner.deployment import deploy_local  # noqa: E402
from core_functions.catalog import ParamSpec, ParamType, skill  # noqa: E402
from core_functions.functions import CoreFunctions, Skill  # noqa: E402
from core_functions.primitives import SetSpeed  # noqa: E402
from core_functions.robots import NEXTAGE_OPEN  # noqa: E402
from execution_engine.app_model.model import Application, Call, ErrorPolicy, Operation  # noqa: E402
from node_transport.clock import Clock, run_with_clock  # noqa: E402
from robot_bridges.backend import BackendOptions  # noqa: E402
from robot_bridges.registry import create_backend  # noqa: E402

try:  # the peer: bench/requirements.txt installs it; the figures of this project do not need it
    import py_trees
except ImportError:
    py_trees = None

#: one py_trees tick in SMACH transitions, from the issue's side-by-side runs (46-52x a transition, 20-22x a tick)
SMACH_TRANSITIONS_PER_TICK = 2.3
AIM_SMACH_TRANSITIONS = 10.0


class BenchFunctions(CoreFunctions):
    @skill(ParamSpec("count", ParamType.INTEGER, "how many primitives", minimum=1), groups=("arm", "torso_head"))
    def speed_sweep(self, count: int) -> Skill:
        """Bench only: ``count`` set_speed primitives in one function."""
        for i in range(count):
            yield SetSpeed(0.5 + 0.5 * (i % 2))


def app(operations: list[dict[str, tuple[str, ...]]]) -> Application:
    ops = []
    for i, calls in enumerate(operations, start=1):
        full = {g: Call(g, "wait", ("0",), implicit=True) for g in NEXTAGE_OPEN.group_names}
        full.update({g: Call(g, f, tuple(p)) for g, (f, *p) in calls.items()})
        ops.append(Operation(str(i), None, i, 1, full))
    return Application("bench", Path("bench.xml"), NEXTAGE_OPEN, None, ErrorPolicy(), tuple(ops))


async def measure(clock: Clock, n: int, chunks: int, peer: Callable[[int], tuple[float, float]] | None) -> list[dict[str, float]]:
    """``chunks`` times, side by side: ``n // chunks`` primitives called directly, as functions, within a
    skill, and as many ticks of the peer; wall and CPU seconds per primitive (per tick), chunk by chunk."""
    m = n // chunks
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
    await backend.start()
    deployment = await deploy_local(clock, NEXTAGE_OPEN, backend, machine_parameters={"trajectory_db": ":memory:"}, bridge_parameters={"state_period": 1.0})
    out = []
    try:
        engine = deployment.engine
        for _ in range(chunks):
            w0, c0 = time.perf_counter(), time.process_time()
            for i in range(m):
                await backend.execute("left_arm", SetSpeed(0.5 + 0.5 * (i % 2)))
            row = {"direct": (time.perf_counter() - w0) / m, "direct_cpu": (time.process_time() - c0) / m}
            for name, application in (("function", app([{"left_arm": ("set_speed", "0.5")} for _ in range(m)])),
                                      ("skill", app([{"left_arm": ("speed_sweep", str(m))}]))):
                for machine in deployment.machines.values():  # the machines restart from Finish for the next application
                    machine.ctx.catalog.functions.update()
                w0, c0 = time.perf_counter(), time.process_time()
                report = await engine.run(application)
                row[name], row[f"{name}_cpu"] = (time.perf_counter() - w0) / m, (time.process_time() - c0) / m
                assert report.ok, report.summary_lines()
            if peer is not None:
                row["tick"], row["tick_cpu"] = peer(m)
            out.append(row)
    finally:
        await deployment.close()
    return out


def tick_peer() -> Callable[[int], tuple[float, float]] | None:
    """Wall and CPU seconds per tick of a py_trees tree doing a primitive's trivial work, ``n`` ticks (None
    without py_trees)."""
    if py_trees is None:
        return None
    speed: dict[str, float] = {}

    class SetSpeedBehaviour(py_trees.behaviour.Behaviour):  # type: ignore[misc]
        def __init__(self) -> None:
            super().__init__("set_speed")
            self.count = 0

        def update(self) -> py_trees.common.Status:
            self.count += 1
            speed["left_arm"] = 0.5 + 0.5 * (self.count % 2)
            return py_trees.common.Status.SUCCESS

    tree = py_trees.trees.BehaviourTree(py_trees.composites.Sequence("primitive", memory=True, children=[SetSpeedBehaviour()]))
    tree.setup()

    def ticks(n: int) -> tuple[float, float]:
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(n):
            tree.tick()
        return (time.perf_counter() - w0) / n, (time.process_time() - c0) / n
    return ticks


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    chunks = 4
    LIBRARIES["bench"] = BenchFunctions
    peer = tick_peer()
    runs = []
    for _ in range(rounds):
        runs.extend(run_with_clock(lambda c: measure(c, n, chunks, peer), Clock(1.0)))
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    us = {k: v * 1e6 for k, v in med.items()}
    result: dict[str, object] = {
        "primitives": n,
        "runs": rounds,
        "direct_us": round(us["direct"], 2),
        "through_engine_one_primitive_per_function_us": round(us["function"], 2),
        "through_machine_within_a_skill_us": round(us["skill"], 2),
        "overhead_per_function_primitive_us": round(us["function"] - us["direct"], 2),
        "overhead_per_skill_primitive_us": round(us["skill"] - us["direct"], 2),
        "ratio_function_vs_direct": round(us["function"] / us["direct"], 1),
        "ratio_skill_vs_direct": round(us["skill"] / us["direct"], 1),
    }
    print(f"{rounds} rounds of {n} primitives, each in {chunks} chunks side by side with the peer; medians, wall (CPU of this process):")
    print(f"direct back-end call:                      {us['direct']:9.2f} us ({us['direct_cpu']:.2f}) per primitive")
    print(f"engine+machine+transport, 1 prim/function: {us['function']:9.2f} us ({us['function_cpu']:.2f}) per primitive")
    print(f"machine+transport, within one skill:       {us['skill']:9.2f} us ({us['skill_cpu']:.2f}) per primitive")
    result.update({f"{k}_cpu_us": round(us[f"{k}_cpu"], 2) for k in ("direct", "function", "skill")})
    if "tick" not in us:
        print("py_trees is not installed (pip install -r bench/requirements.txt): no factor against the peer")
        result.update(py_trees_tick_us=None, function_vs_tick=None, skill_vs_tick=None)
    else:
        # the factors in CPU time: on a shared machine, wall time counts whoever else had the core
        factors = {k: sorted(r[f"{k}_cpu"] / r["tick_cpu"] for r in runs) for k in ("function", "skill")}
        aim = AIM_SMACH_TRANSITIONS / SMACH_TRANSITIONS_PER_TICK
        print(f"py_trees {py_trees.version.__version__} tick (peer):            {us['tick']:9.2f} us ({us['tick_cpu']:.2f}) per tick")
        for k, label in (("function", "one primitive per function"), ("skill", "a primitive within a skill")):
            f = statistics.median(factors[k])
            print(f"{label}: {f:5.1f} py_trees ticks of CPU (chunks {factors[k][0]:.1f}-{factors[k][-1]:.1f}), "
                  f"about {f * SMACH_TRANSITIONS_PER_TICK:.0f} SMACH transitions; aim {AIM_SMACH_TRANSITIONS:g} transitions = {aim:.1f} ticks")
        result.update(
            py_trees_version=py_trees.version.__version__,
            py_trees_tick_us=round(us["tick"], 2),
            py_trees_tick_cpu_us=round(us["tick_cpu"], 2),
            function_vs_tick=round(statistics.median(factors["function"]), 2),
            function_vs_tick_range=[round(factors["function"][0], 2), round(factors["function"][-1], 2)],
            skill_vs_tick=round(statistics.median(factors["skill"]), 2),
            skill_vs_tick_range=[round(factors["skill"][0], 2), round(factors["skill"][-1], 2)],
            aim_ticks=round(aim, 2),
        )
    print(json.dumps(result))


if __name__ == "__main__":
    main()
