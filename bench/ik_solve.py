"""Nextage arm IK solve time: near targets (a Cartesian step from the current pose), far targets.

Every Cartesian primitive of the simulator solves IK once (ptp) or once per 5 mm of path
(linear), so the solve time bounds how fast the simulator plans.  The baseline, measured in the
same run on the same arm model, is one pinocchio forward-kinematics + frame-Jacobian evaluation:
the ratio says how many such evaluations a solve costs.

    python bench/ik_solve.py [--near 2000] [--far 300] [--seed 1]

Prints human-readable lines, then one JSON object as the last line.
"""
from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np
import pinocchio as pin

from core_functions.geometry import Pose
from robot_bridges.backend import BridgeError
from robot_bridges.nextage_sim.model import ArmKinematics, NextageModel


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q))


def realistic(arm: ArmKinematics, rng: np.random.Generator) -> np.ndarray:
    """A random arm configuration 10% inside every limit (the working region, not the corners)."""
    margin = 0.1 * (arm.upper - arm.lower)
    return rng.uniform(arm.lower + margin, arm.upper - margin)


def time_baseline(arm: ArmKinematics, configs: list[np.ndarray]) -> list[float]:
    times = []
    for q in configs:
        start = time.perf_counter()
        pin.framesForwardKinematics(arm.model, arm.data, q)
        pin.computeFrameJacobian(arm.model, arm.data, q, arm.frame_id, pin.LOCAL_WORLD_ALIGNED)
        times.append(time.perf_counter() - start)
    return times


def time_solves(arm: ArmKinematics, cases: list[tuple[Pose, np.ndarray]]) -> tuple[list[float], int, list[int]]:
    times, failures, attempts = [], 0, []
    for target, seed in cases:
        start = time.perf_counter()
        try:
            attempts.append(arm.solve(target, seed).attempts)
        except BridgeError:
            failures += 1
        times.append(time.perf_counter() - start)
    return times, failures, attempts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--near", type=int, default=2000, help="near-target solves")
    parser.add_argument("--far", type=int, default=300, help="far-target solves")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()

    model = NextageModel()
    arm = model.arms["left_arm"]
    rng = np.random.default_rng(args.seed)
    base = model.named_pose("initial")

    near_cases: list[tuple[Pose, np.ndarray]] = []
    for _ in range(args.near):
        q = base.copy()
        q[arm.indices] = realistic(arm, rng)
        target_q = q.copy()
        target_q[arm.indices] = np.clip(q[arm.indices] + rng.uniform(-0.05, 0.05, 6), arm.lower, arm.upper)
        near_cases.append((arm.tcp_pose(target_q), q))  # a few cm / degrees from the current pose
    far_cases: list[tuple[Pose, np.ndarray]] = []
    for _ in range(args.far):
        target_q = base.copy()
        target_q[arm.indices] = realistic(arm, rng)
        far_cases.append((arm.tcp_pose(target_q), base))  # anywhere, solved from the initial pose

    baseline = time_baseline(arm, [q[arm.indices] for _, q in near_cases])
    near, near_fail, near_attempts = time_solves(arm, near_cases)
    far, far_fail, far_attempts = time_solves(arm, far_cases)

    base_med = statistics.median(baseline)
    figures = {
        "baseline_fk_jacobian_median_us": round(base_med * 1e6, 2),
        "near_median_us": round(statistics.median(near) * 1e6, 1),
        "near_p99_us": round(percentile(near, 99) * 1e6, 1),
        "near_ratio_to_baseline": round(statistics.median(near) / base_med, 1),
        "near_failures": near_fail,
        "near_restarts_used": sum(a > 1 for a in near_attempts),
        "far_median_us": round(statistics.median(far) * 1e6, 1),
        "far_p99_us": round(percentile(far, 99) * 1e6, 1),
        "far_ratio_to_baseline": round(statistics.median(far) / base_med, 1),
        "far_failures": far_fail,
        "far_solved_first_attempt": sum(a == 1 for a in far_attempts),
        "near_cases": len(near),
        "far_cases": len(far),
    }
    print(f"baseline: pinocchio FK + frame Jacobian (6-joint arm)  median {figures['baseline_fk_jacobian_median_us']} us")
    print(
        f"near targets ({len(near)}): median {figures['near_median_us']} us, p99 {figures['near_p99_us']} us, "
        f"x{figures['near_ratio_to_baseline']} baseline, {near_fail} failed, {figures['near_restarts_used']} needed restarts"
    )
    print(
        f"far targets ({len(far)}):  median {figures['far_median_us']} us, p99 {figures['far_p99_us']} us, "
        f"x{figures['far_ratio_to_baseline']} baseline, {far_fail} failed, "
        f"{figures['far_solved_first_attempt']} solved from the initial pose without restarts"
    )
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
