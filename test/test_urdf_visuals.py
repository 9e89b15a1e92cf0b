"""The robots' URDFs carry visuals, so RViz's RobotModel display and Foxglove draw the robot.

RViz draws a link's ``<visual>`` elements by default and its ``<collision>`` elements only when
"Collision Enabled" is ticked; with collision shapes alone (as the URDFs had) a RobotModel display
stays empty although its status says the URDF is fine.  The visuals are the collision shapes
(boxes and cylinders, no meshes, so nothing a viewer must resolve through ``package://``),
coloured through materials defined once at the top of the file: urdfdom (RViz's parser) refuses a
model whose visual names a material it has not seen with a colour.
"""
from __future__ import annotations

from pathlib import Path

import pinocchio as pin
import pytest
from lxml import etree

ROOT = Path(__file__).resolve().parents[1] / "robot_bridges"
URDFS = {
    "nextage": ROOT / "nextage_sim" / "urdf" / "nextage_open.urdf",
    "viper": ROOT / "vplus" / "urdf" / "adept_viper_s850.urdf",
    "kuka": ROOT / "kuka_rsi" / "urdf" / "kuka_kr6_r900.urdf",
}


def _robot(name: str) -> etree._Element:
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    return etree.fromstring(URDFS[name].read_bytes(), parser)


def _shape(element: etree._Element) -> tuple[str, str]:
    """The origin and geometry of a visual or collision element, as text to compare."""
    origin = element.find("origin")
    geometry = element.find("geometry")
    assert geometry is not None and len(geometry) == 1
    return (etree.tostring(origin).decode() if origin is not None else "",
            etree.tostring(geometry[0]).decode())


@pytest.mark.parametrize("name", sorted(URDFS))
def test_every_link_with_a_collision_shape_is_drawn_as_that_shape(name: str) -> None:
    robot = _robot(name)
    links = robot.findall("link")
    assert links
    for link in links:
        collisions = link.findall("collision")
        visuals = link.findall("visual")
        assert [_shape(v) for v in visuals] == [_shape(c) for c in collisions], link.get("name")
        for visual in visuals:
            assert visual.find("geometry/mesh") is None  # nothing to resolve through package://


@pytest.mark.parametrize("name", sorted(URDFS))
def test_every_visual_names_a_material_defined_with_a_colour(name: str) -> None:
    robot = _robot(name)
    colours = {m.get("name"): m.find("color").get("rgba") for m in robot.findall("material")}
    used = [v.find("material").get("name") for link in robot.findall("link") for v in link.findall("visual")]
    assert used
    assert set(used) <= set(colours)
    for rgba in colours.values():
        values = [float(x) for x in rgba.split()]
        assert len(values) == 4 and all(0.0 <= x <= 1.0 for x in values) and values[3] == 1.0


@pytest.mark.parametrize("name", sorted(URDFS))
def test_a_urdf_parser_builds_one_coloured_visual_per_drawn_link(name: str) -> None:
    xml = URDFS[name].read_text(encoding="utf-8")
    model = pin.buildModelFromXML(xml)
    visuals = pin.buildGeomFromUrdfString(model, xml, pin.GeometryType.VISUAL)
    drawn = [link.get("name") for link in _robot(name).findall("link") if link.find("visual") is not None]
    assert sorted(o.name.rsplit("_", 1)[0] for o in visuals.geometryObjects) == sorted(drawn)
    assert all(o.meshColor[3] == 1.0 and max(o.meshColor[:3]) > 0.0 for o in visuals.geometryObjects)
