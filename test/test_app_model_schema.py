"""The XSDs, how they are found, and that they agree with the robots and the reader."""
from __future__ import annotations

from pathlib import Path

import pytest

from core_functions.robots import ROBOTS
from core_functions import resources
from execution_engine.app_model.reader import GROUP_TAGS
from execution_engine.app_model.schema import load_schema


def test_the_application_schema_knows_every_group_of_every_robot() -> None:
    info = load_schema("application")
    groups = set(info.children["operation"])
    assert groups == set(GROUP_TAGS)
    assert {g for robot in ROBOTS for g in robot.group_names} <= groups


def test_every_attribute_type_has_plain_words() -> None:
    for name in ("application", "cell"):
        info = load_schema(name)
        for element, attributes in info.attributes.items():
            for attribute, type_name in attributes.items():
                assert type_name.startswith("xs:") or type_name in info.type_docs, (name, element, attribute, type_name)


def test_share_path_prefers_the_environment(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "apps_xml" / "schema").mkdir(parents=True)
    (tmp_path / "apps_xml" / "schema" / "application.xsd").write_text("<x/>")
    monkeypatch.setenv(resources.ENV_VAR, str(tmp_path))
    assert resources.share_path("apps_xml", "schema", "application.xsd") == tmp_path / "apps_xml" / "schema" / "application.xsd"
    # Files the override lacks come from the next place: the source tree.
    cell = resources.share_path("apps_xml", "schema", "cell.xsd")
    assert cell == Path(resources.__file__).resolve().parent.parent / "apps_xml" / "schema" / "cell.xsd"


def test_share_path_says_where_it_looked(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(resources.ENV_VAR, str(tmp_path))
    with pytest.raises(FileNotFoundError) as caught:
        resources.share_path("apps_xml", "nothing.xml")
    assert str(tmp_path / "apps_xml" / "nothing.xml") in str(caught.value)
    assert "share/dual_arm_executive" in str(caught.value)
