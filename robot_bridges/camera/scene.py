"""The cell as the simulator's cameras see it: part surfaces with their holes, trays with rivets.

Built from the engine's cell snapshot: every frame with an image model
(:func:`core_functions.vision.features.feature_model`) is drawn where it *really* is (the cell's
``truth``, from its ``<actual>`` offsets) on a surface standing for its parent (the part, the
tray), itself at its true pose and large enough to hold all its features.
"""
from __future__ import annotations

from collections import defaultdict

import numpy as np

from core_functions.cell_index import CellFrame
from core_functions.geometry import Pose
from core_functions.vision.features import FeatureModel, feature_model
from robot_bridges.camera.render import Disc, Lighting, Scene, Surface

#: Surface margin around its outermost feature (m).
MARGIN = 0.03
#: Relative brightness of a part surface, a tray, the inside of a hole, a rivet head.
PART_ALBEDO, TRAY_ALBEDO, HOLE_ALBEDO, HEAD_ALBEDO = 0.75, 0.3, 0.06, 0.95


def true_pose(frames: dict[str, CellFrame], truth: dict[str, Pose], name: str) -> Pose | None:
    if name in truth:
        return truth[name]
    frame = frames.get(name)
    return None if frame is None else frame.pose


def build_scene(frames: tuple[CellFrame, ...], elements: dict[str, dict[str, str]], truth: dict[str, Pose], lighting: Lighting | None = None) -> Scene:
    """One surface per parent of visible features (a feature parented to the world gets its own)."""
    by_name = {f.name: f for f in frames}
    groups: dict[str, list[tuple[CellFrame, FeatureModel]]] = defaultdict(list)
    for frame in frames:
        try:
            model = feature_model(frame, elements)
        except ValueError:
            continue  # the locate of that frame says why; the rest of the cell still renders
        if model is not None:
            groups[frame.parent if frame.parent in by_name else frame.name].append((frame, model))
    surfaces = []
    for parent, members in groups.items():
        base = true_pose(by_name, truth, parent)
        if base is None:
            continue
        inverse = np.linalg.inv(base.matrix())
        discs, extent = [], np.zeros(2)
        for frame, model in members:
            if frame.attributes.get("drilled") == "false":  # a hole the CAD has and the part lacks: plain surface (the locate fails)
                continue
            where = true_pose(by_name, truth, frame.name) or frame.pose
            local = inverse @ where.matrix()
            x, y = float(local[0, 3]), float(local[1, 3])
            albedo = HOLE_ALBEDO if model.polarity == "dark" else HEAD_ALBEDO
            discs.append(Disc(x, y, model.diameter, albedo))
            extent = np.maximum(extent, np.abs([x, y]) + 0.5 * model.diameter)
        kind = by_name[parent].kind if parent in by_name else ""
        albedo = TRAY_ALBEDO if "tray" in kind or all(m.polarity == "bright" for _, m in members) else PART_ALBEDO
        half = (float(extent[0] + MARGIN), float(extent[1] + MARGIN))
        surfaces.append(Surface(base.matrix(), half, albedo, tuple(discs)))
    return Scene(tuple(surfaces), lighting or Lighting())
