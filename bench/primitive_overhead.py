"""Overhead per primitive: engine + group machine + transport + bridge node, vs calling the back end directly.

Both sides execute the same primitives on the same Nextage simulator back end, in one process and one run, on
real (wall) time:

* direct:   ``await backend.execute("left_arm", SetSpeed(f))`` N times;
* function: an application of N operations, each one ``set_speed`` on left_arm (one primitive per function, so the
            engine's dispatch, result and Ready check are paid for every primitive: the worst case);
* skill:    one operation whose function yields N primitives (what a real skill does: the machine and transport
            are paid per primitive, the engine once).

``set_speed`` does no motion, so the direct figure is the back end's own cost and the differences are pure
orchestration overhead.  Run:  python bench/primitive_overhead.py [N]
"""
from __future__ import annotations

import asyncio
import json
import statistics
import sys
import time
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


async def measure(clock: Clock, n: int) -> dict[str, float]:
    backend = await create_backend("nextage-sim", clock, BackendOptions(robot=NEXTAGE_OPEN))
    await backend.start()
    t0 = time.perf_counter()
    for i in range(n):
        await backend.execute("left_arm", SetSpeed(0.5 + 0.5 * (i % 2)))
    direct = (time.perf_counter() - t0) / n

    deployment = await deploy_local(clock, NEXTAGE_OPEN, backend, machine_parameters={"trajectory_db": ":memory:"}, bridge_parameters={"state_period": 1.0})
    try:
        engine = deployment.engine
        per_function_app = app([{"left_arm": ("set_speed", "0.5")} for _ in range(n)])
        t0 = time.perf_counter()
        report = await engine.run(per_function_app)
        function = (time.perf_counter() - t0) / n
        assert report.ok, report.summary_lines()
        skill_app = app([{"left_arm": ("speed_sweep", str(n))}])
        for machine in deployment.machines.values():  # the machines restart from Finish for the next application
            machine.ctx.catalog.functions.update()
        t0 = time.perf_counter()
        report = await engine.run(skill_app)
        in_skill = (time.perf_counter() - t0) / n
        assert report.ok, report.summary_lines()
    finally:
        await deployment.close()
    return {"direct": direct, "function": function, "skill": in_skill}


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 2000
    LIBRARIES["bench"] = BenchFunctions
    runs = [run_with_clock(lambda c: measure(c, n), Clock(1.0)) for _ in range(3)]
    med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
    us = {k: v * 1e6 for k, v in med.items()}
    result = {
        "primitives": n,
        "runs": len(runs),
        "direct_us": round(us["direct"], 2),
        "through_engine_one_primitive_per_function_us": round(us["function"], 2),
        "through_machine_within_a_skill_us": round(us["skill"], 2),
        "overhead_per_function_primitive_us": round(us["function"] - us["direct"], 2),
        "overhead_per_skill_primitive_us": round(us["skill"] - us["direct"], 2),
        "ratio_function_vs_direct": round(us["function"] / us["direct"], 1),
        "ratio_skill_vs_direct": round(us["skill"] / us["direct"], 1),
    }
    print(f"direct back-end call:                     {us['direct']:9.2f} us per primitive")
    print(f"engine+machine+transport, 1 prim/function: {us['function']:9.2f} us per primitive")
    print(f"machine+transport, within one skill:       {us['skill']:9.2f} us per primitive")
    print(json.dumps(result))


if __name__ == "__main__":
    main()
