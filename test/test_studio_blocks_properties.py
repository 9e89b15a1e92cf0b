"""The builder's document as the page sends it is input from outside: any JSON is refused in one line or taken,
and whatever is taken is written through lxml and read back as the same document (hypothesis)."""
from __future__ import annotations

from typing import Any

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from execution_engine.app_model.document import DocumentError
from operator_station.blocks import BLOCK_KINDS, BlockDocument
from operator_station.blocks_xml import parse_blocks, write_blocks

TEXT = st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=12)  # what JSON can carry
COMMENT = st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="-\r"), max_size=12)  # '--' and CR are rewritten
JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | TEXT,
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.sampled_from(["type", "id", "calls", "attributes", "body", "params", "name", "value", "group", "function", "comments"]) | TEXT, inner, max_size=5),
                    max_leaves=30)
GROUP = st.sampled_from(["left_arm", "right_arm", "torso_head"]) | TEXT
PARAM = st.fixed_dictionaries({"value": TEXT, "name": st.none() | TEXT})
CALL = st.fixed_dictionaries({"group": GROUP, "function": TEXT, "params": st.lists(PARAM, max_size=2)})
OPERATION = st.fixed_dictionaries({"type": st.just("operation"), "id": TEXT, "name": st.none() | TEXT, "comments": st.lists(COMMENT, max_size=1),
                                   "calls": st.lists(CALL, max_size=2, unique_by=lambda c: c["group"])},
                                  optional={"inner": st.dictionaries(st.sampled_from(["", "left_arm", "right_arm"]), st.lists(COMMENT, min_size=1, max_size=2), max_size=2)})


def block(inner: Any) -> Any:
    def made(kind: str) -> Any:
        spec = BLOCK_KINDS[kind]
        attributes = st.fixed_dictionaries({name: TEXT for name in spec.required}, optional={name: TEXT for name in spec.attributes if name not in spec.required})
        return st.fixed_dictionaries({
            "type": st.just(kind), "attributes": attributes, "comments": st.lists(COMMENT, max_size=1), "trailer": st.lists(COMMENT, max_size=1),
            "params": st.lists(st.fixed_dictionaries({"name": TEXT, "value": TEXT}), max_size=2) if spec.params else st.just([]),
            "body": st.lists(inner, max_size=3) if spec.body else st.just([]),
        })
    return st.sampled_from(sorted(BLOCK_KINDS)).flatmap(made)


STEPS = st.recursive(OPERATION, lambda inner: block(inner), max_leaves=8)
DOCUMENT = st.fixed_dictionaries({
    "name": TEXT, "robot": TEXT, "cell": st.none() | TEXT, "version": st.none() | TEXT, "description": st.none() | TEXT,
    "error_policy": st.none() | st.fixed_dictionaries({}, optional={"retries": TEXT, "action": TEXT}),
    "header": st.lists(COMMENT, max_size=1), "trailer": st.lists(COMMENT, max_size=1),
    "sync": st.sampled_from([None, "operation", "flags"]), "body": st.lists(STEPS, max_size=4),
})


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(JSON, st.fixed_dictionaries({"name": TEXT, "robot": TEXT, "body": JSON})))
def test_any_json_is_taken_or_refused_in_one_line(data: Any) -> None:
    try:
        BlockDocument.from_json(data)
    except DocumentError as error:
        assert str(error) and "\n" not in str(error)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(DOCUMENT)
def test_any_document_taken_is_written_and_read_back_the_same_or_refused_in_one_line(data: dict[str, Any]) -> None:
    try:
        document = BlockDocument.from_json(data)
        text, lines = write_blocks(document)
    except DocumentError as error:
        assert str(error) and "\n" not in str(error)
        return
    back, problems = parse_blocks(text.encode("utf-8"), "app.xml")
    assert back == document, problems
    assert len(lines) == text.count("\n") + 1
