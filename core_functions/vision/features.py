"""What a cell frame looks like to a camera: the feature model the renderer draws and the detector seeks.

One table for both sides, so the simulator never renders a feature the detector is not told
about.  A frame with a ``diameter`` attribute is a drilled hole (a dark disc of that diameter,
the ``hole`` kind of the cell models); a ``rivet_slot`` frame shows the head of its rivet, a
bright disc of the element's ``head_diameter`` (default 1.6 x its ``diameter``).  Optional
attributes: ``polarity`` (dark/bright) and ``search_radius`` (m: how far from its nominal
position the feature may really be; default :data:`SEARCH_RADIUS`).  Other frames (fixtures,
trays, views) have no image model.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from core_functions.cell_index import CellFrame
from core_functions.vision.detect import Polarity

#: Default search radius around the nominal position (m): a few mm of fixture and drilling error,
#: well inside the spacing of neighbouring holes.
SEARCH_RADIUS = 0.005
#: Rivet head diameter relative to its shank when the element does not give ``head_diameter``.
HEAD_FACTOR = 1.6


@dataclass(frozen=True)
class FeatureModel:
    """A circular feature: diameter (m), dark or bright, how far from nominal to look (m)."""

    diameter: float
    polarity: Polarity = "dark"
    search_radius: float = SEARCH_RADIUS


def _number(attributes: Mapping[str, str], key: str, where: str) -> float | None:
    text = attributes.get(key)
    if text is None:
        return None
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"{where}: {key} {text!r} is not a number") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{where}: {key} must be a positive length in m, got {text!r}")
    return value


def feature_model(frame: CellFrame, elements: Mapping[str, Mapping[str, str]]) -> FeatureModel | None:
    """The image model of ``frame``, or None when a camera cannot recognise it (ValueError on bad attributes)."""
    where = f"frame {frame.name!r}"
    attributes = frame.attributes
    diameter = _number(attributes, "diameter", where)
    polarity: Polarity = "dark"
    if frame.kind == "rivet_slot":
        element = elements.get(attributes.get("element", ""), {})
        head = _number(element, "head_diameter", f"element {attributes.get('element')!r}")
        shank = _number(element, "diameter", f"element {attributes.get('element')!r}")
        diameter = head or (shank * HEAD_FACTOR if shank else None)
        polarity = "bright"
    if diameter is None:
        return None
    chosen = attributes.get("polarity", polarity)
    if chosen not in ("dark", "bright"):
        raise ValueError(f"{where}: polarity must be dark or bright, got {chosen!r}")
    radius = _number(attributes, "search_radius", where) or SEARCH_RADIUS
    return FeatureModel(diameter, "dark" if chosen == "dark" else "bright", radius)
