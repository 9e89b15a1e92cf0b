"""Vision accuracy and speed: holes located from rendered images, against where they really are.

Each trial puts a part (a plate with a drilled hole of 4.8 mm and neighbours 40 mm away) at a
random pose in the world, the hole up to 3 mm from its nominal position, and a camera at a random
distance (50-90 mm) and view angle (up to 35 degrees) aimed near the nominal hole, with random
sensor noise, lighting gradient and defocus (focus 85-120 % of the distance).  The image is
rendered (robot_bridges.camera.render) and the hole located by the Vision state's own function
(core_functions.vision.locate.locate).  Accuracy: the distance between the located and the true
centre in the world frame.  Speed: the time of the whole locate per image beside one bare
``cv2.GaussianBlur`` (sigma 2) of the same image, measured in the same run.

    python bench/vision_accuracy.py [--trials 240] [--seed 1]

Prints human-readable lines, then one JSON object as the last line.
"""
from __future__ import annotations

import argparse
import json
import math
import time

import cv2
import numpy as np

from core_functions.geometry import Pose
from core_functions.vision.camera import Intrinsics
from core_functions.vision.features import FeatureModel
from core_functions.vision.locate import View, VisionFault, locate
from robot_bridges.camera.render import Disc, Lighting, Optics, Scene, Surface, render

DIAMETER = 0.0048
INTRINSICS = Intrinsics.from_fov(640, 480, math.radians(60.0))


def trial(rng: np.random.Generator) -> tuple[View, Pose, Pose]:
    """(view, nominal hole pose, true hole pose) of one random scene; the hole frame's z points into the part."""
    part = Pose.from_xyz_rpy(*rng.uniform(-0.3, 0.3, 3), *rng.uniform(-0.3, 0.3, 2), rng.uniform(-math.pi, math.pi))
    into = Pose.from_xyz_rpy(0, 0, 0, math.pi, 0, 0)  # z into the part
    offset = rng.uniform(0, 0.003) * np.array([math.cos(a := rng.uniform(0, 2 * math.pi)), math.sin(a)])
    nominal = part.compose(into)
    truth = part.compose(Pose(float(offset[0]), float(offset[1]), 0.0)).compose(into)
    discs = (Disc(float(offset[0]), float(offset[1]), DIAMETER, 0.06), Disc(0.04, 0.0, DIAMETER, 0.06), Disc(-0.04, 0.0, DIAMETER, 0.06))
    scene = Scene((Surface(part.matrix(), (0.08, 0.06), rng.uniform(0.5, 0.85), discs),), Lighting(tuple(rng.uniform(-0.4, 0.4, 2)), rng.uniform(0, 0.3)))  # type: ignore[arg-type]
    distance, tilt = rng.uniform(0.05, 0.09), rng.uniform(0.0, math.radians(35))
    aim = nominal.compose(Pose(*rng.uniform(-0.004, 0.004, 2), 0.0))
    camera = aim.compose(Pose.from_xyz_rpy(0, 0, 0, 0, 0, rng.uniform(-math.pi, math.pi))).compose(Pose.from_xyz_rpy(0, 0, 0, tilt, 0, 0)).compose(Pose(0, 0, -distance))
    optics = Optics(distance * rng.uniform(0.85, 1.2), aperture=0.002, read_noise=rng.uniform(0.0, 0.025))
    image = render(scene, INTRINSICS, camera.matrix(), optics, rng)
    return View("bench_camera", image, INTRINSICS, camera), nominal, truth


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=240)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    model = FeatureModel(DIAMETER)
    errors, located_s, blur_s, failures = [], [], [], []
    for i in range(args.trials):
        view, nominal, truth = trial(rng)
        start = time.perf_counter()
        cv2.GaussianBlur(view.image, (0, 0), 2.0)
        blur_s.append(time.perf_counter() - start)
        start = time.perf_counter()
        try:
            found = locate([view], "hole", nominal, model)
        except VisionFault as error:
            failures.append(f"trial {i}: {error}")
            continue
        located_s.append(time.perf_counter() - start)
        errors.append(found.pose.distance_to(truth))
    mm = np.array(errors) * 1000
    p50, p95, worst = (float(np.percentile(mm, q)) for q in (50, 95, 100))
    t_locate, t_blur = float(np.median(located_s)) * 1000, float(np.median(blur_s)) * 1000
    print(f"holes located: {len(errors)} of {args.trials} ({len(failures)} VISION faults)")
    for line in failures[:5]:
        print(f"  {line}")
    print(f"world-frame centre error: p50 {p50:.4f} mm  p95 {p95:.4f} mm  max {worst:.4f} mm  (aim p95 <= 0.05 mm; process needs 0.2 mm)")
    print(f"time per 640x480 image: locate {t_locate:.2f} ms  bare cv2.GaussianBlur {t_blur:.3f} ms  ratio {t_locate / t_blur:.0f}x")
    print(json.dumps({"trials": args.trials, "located": len(errors), "faults": len(failures), "p50_mm": round(p50, 5), "p95_mm": round(p95, 5), "max_mm": round(worst, 5), "locate_ms": round(t_locate, 3), "gaussian_blur_ms": round(t_blur, 4), "ratio": round(t_locate / t_blur, 1)}))


if __name__ == "__main__":
    main()
