"""What validates, runs: the cell model and every request fit the transport's message limit.

A cell of 31,000 frames (2.8 MB) used to pass validate; its snapshot was then over the codec's
4 MiB and every group machine refused it.  validate now sizes what the engine will send, against
the codec's own limit, and refuses with the reason.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest
from app_model_support import APP_XML, CELL_XML, at, small_catalog
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core_functions.catalog import Catalog, ParamSpec, ParamType, skill
from core_functions.geometry import Pose
from core_functions.robots import NEXTAGE_OPEN
from execution_engine.app_model import Cell, Element, Frame, JointPose, load_application, validate_application, validate_cell
from execution_engine.app_model import wire_fit
from execution_engine.app_model.cell import read_cell_log
from node_transport import codec
from node_transport.wire import CellSnapshot

CATALOG = small_catalog()
TOO_LARGE = "is too large to run: its model with {frames} frames, 0 elements and 0 joint poses is over 4,194,304 bytes as a message"


def many_frames(n: int) -> str:
    frames = "".join(
        f'  <frame name="hole_{i}" xyz="{i % 300}.5 {i % 7}.25 0" rpy="180 0 90" kind="hole" diameter="0.0048"/>\n' for i in range(n)
    )
    return f'<?xml version="1.0"?>\n<cell name="big" length_unit="mm" angle_unit="deg">\n{frames}</cell>\n'


# ------------------------------------------------------------------------------ the cell model
def test_a_31000_frame_cell_is_refused_by_validate_as_every_machine_would(tmp_path: Path) -> None:
    path = tmp_path / "big.xml"
    path.write_text(many_frames(31_000))
    assert 2.5e6 < path.stat().st_size < 3.2e6  # the 2.8 MB of the report
    assert [str(d) for d in validate_cell(path)] == [f"{path}:2:1: cell file {path} {TOO_LARGE.format(frames='31,000')}"
                                                     " (the transport's limit, node_transport.codec.MAX_MESSAGE_BYTES), and every "
                                                     "group machine would refuse it; split the cell or leave out what this application does not use"]
    cell, _ = read_cell_log(path, fits=False)
    assert cell is not None
    with pytest.raises(codec.WireError, match="exceeds the limit"):
        codec.decode(CellSnapshot, codec.encode(cell.to_snapshot()))  # what a group machine does with it


def test_a_cell_that_fits_validates_and_is_received(tmp_path: Path) -> None:
    path = tmp_path / "fits.xml"
    path.write_text(many_frames(3_000))
    assert validate_cell(path) == []
    cell, _ = read_cell_log(path)
    assert cell is not None
    text = codec.encode(cell.to_snapshot())
    assert wire_fit.snapshot_size(cell) == len(text.encode())
    assert len(codec.decode(CellSnapshot, text).frames) == 3_000


def test_an_application_with_a_cell_too_large_says_so_at_its_cell_and_still_checks_its_names(tmp_path: Path) -> None:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(many_frames(31_000).replace('name="hole_5"', 'name="drill_1"'))
    text = APP_XML.replace('<param value="drill_2"/>', '<param value="hole_x"/>')
    path = tmp_path / "app.xml"
    path.write_text(text)
    found = [str(d) for d in validate_application(path, CATALOG)]
    assert found[0] == at(path, text, 'cell="', f"cell file {tmp_path / 'cells' / 'rivet_cell.xml'} {TOO_LARGE.format(frames='31,000')}"
                          " (the transport's limit, node_transport.codec.MAX_MESSAGE_BYTES), and every group machine "
                          "would refuse it; split the cell or leave out what this application does not use")
    assert any("unknown frame 'hole_x' in the cell model" in line for line in found)


_NAMES = st.text(alphabet=st.sampled_from(list("ab_.-é\"\\ü")), min_size=1, max_size=6).map(lambda s: "f" + s)
_TEXTS = st.text(alphabet=st.sampled_from(list("0.5 é\"\\<&'\u20ac\U0001f600")), max_size=8)


@settings(suppress_health_check=[HealthCheck.too_slow], deadline=None, max_examples=60)
@given(
    names=st.lists(_NAMES, unique=True, max_size=12),
    attributes=st.dictionaries(st.sampled_from(["diameter", "note", "element"]), _TEXTS, max_size=3),
    offsets=st.lists(st.floats(-100, 100, allow_nan=False), min_size=3, max_size=3),
    actual=st.booleans(),
    poses=st.integers(0, 3),
)
def test_the_snapshot_is_sized_to_the_byte(names: list[str], attributes: dict[str, str], offsets: list[float], actual: bool, poses: int) -> None:
    frames: dict[str, Frame] = {}
    for i, name in enumerate(names):
        parent = names[i // 2] if i else "world"
        local = Pose.from_xyz_rpy(*offsets, 0.1 * i, 0, math.pi)
        frames[name] = Frame(name, parent, local, "hole", dict(attributes), Pose.from_xyz_rpy(0.001, 0, 0) if actual and i % 3 == 0 else None)
    joint_poses = {f"p{k}": JointPose(f"p{k}", (0.1 * k,) * 6, "left_arm") for k in range(poses)}
    cell = Cell("c é", frames, {"r": Element("r", "rivet", {"length": "0.01"})}, joint_poses).bind(NEXTAGE_OPEN)
    assert wire_fit.snapshot_size(cell) == len(codec.encode(cell.to_snapshot()).encode("utf-8"))


# ------------------------------------------------------------------------------ the requests
class Talk:
    @skill(groups=("arm", "torso_head"))
    def wait(self) -> None:
        """Sit this operation out."""

    @skill(ParamSpec("message", ParamType.TEXT, "what to say"))
    def say(self, message: str) -> None:
        """Say something."""


def talk_app(tmp_path: Path, message: str) -> tuple[Path, str]:
    text = (f'<application name="t" robot="nextage">\n<operation id="1">\n'
            f'<left_arm><function name="say"><params><param value="{message}"/></params></function></left_arm>\n</operation>\n</application>\n')
    path = tmp_path / "talk.xml"
    path.write_text(text)
    return path, text


def test_a_request_over_the_limit_is_refused_at_its_call(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    talk = Catalog.from_classes({"talk": Talk})
    path, text = talk_app(tmp_path, "x" * 4000)
    assert validate_application(path, talk) == []
    monkeypatch.setattr(codec, "MAX_MESSAGE_BYTES", 3000)  # what the check reads: the codec's own number
    found = [str(d) for d in validate_application(path, talk)]
    assert len(found) == 1 and found[0].startswith(at(path, text, "<function", "the request for say on left_arm in operation 1 would be "))
    assert found[0].endswith("bytes, over the transport's limit of 3,000 (node_transport.codec.MAX_MESSAGE_BYTES); shorten its params")


def test_requests_far_below_the_limit_are_not_encoded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    built: list[object] = []
    original = wire_fit.SmRequest
    monkeypatch.setattr(wire_fit, "SmRequest", lambda *a, **k: built.append(1) or original(*a, **k))
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    path = tmp_path / "app.xml"
    path.write_text(APP_XML.replace("</application>", "".join(APP_XML[APP_XML.index('  <operation id="3">'):APP_XML.index("</application>")]
                                                              .replace('id="3"', f'id="x{i}"') for i in range(200)) + "</application>"))
    assert load_application(path, CATALOG).operations
    assert len(built) == 1  # the one request that measures the fixed part; each call is bounded from above
