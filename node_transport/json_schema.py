"""JSON Schemas (draft 2020-12) of the wire messages, derived from their dataclasses by the codec's rules.

The contract of a JSON message is its dataclass in :mod:`node_transport.wire` read
the way :mod:`node_transport.codec` reads it.  Tools that are not this Python
package -- a viewer, a log checker, a test rig on another machine -- need that contract in a
standard form, so this module turns it into one schema per message type.  The schemas are
generated, never written by hand: the field plan (JSON key, required or not) comes from the
codec itself, and every type form the codec decodes has exactly one schema form here.  A test
compares the committed copies under ``schema/json`` with what this module produces now.

What a schema cannot say, the decoder still checks: the size limit and each dataclass's own
``__post_init__`` rules (an execute command carries a primitive, a quaternion has unit length).

    python -m node_transport.json_schema --out schema/json    # regenerate
    python -m node_transport.json_schema --check schema/json  # exit 1 if stale
"""
from __future__ import annotations

import argparse
import dataclasses
import enum
import inspect
import json
import sys
import types
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin

from node_transport import codec
from node_transport.wire import (
    ENGINE_CELL,
    ENGINE_EVENTS,
    ENGINE_STATUS,
    PROTOCOL_VERSION,
    SYNC_TOPIC,
    BridgeCommand,
    BridgeFeedback,
    CellSnapshot,
    EngineEvent,
    EngineStatus,
    LocatedFrames,
    SmRequest,
    SmResult,
    SmStatus,
    SmStructure,
    SyncMessage,
    bridge_topic,
    sm_topic,
)

GROUP = "<group>"  # stands for a robot group's name in the topic names of the index
# The one registry of top-level messages: the topic (relative, as the nodes resolve it under their
# namespace) and the dataclass it carries.  A new wire message needs one line here.
MESSAGES: tuple[tuple[str, type], ...] = (
    (sm_topic(GROUP, "request"), SmRequest),
    (sm_topic(GROUP, "result"), SmResult),
    (sm_topic(GROUP, "status"), SmStatus),
    (sm_topic(GROUP, "structure"), SmStructure),
    (bridge_topic(GROUP, "command"), BridgeCommand),
    (bridge_topic(GROUP, "feedback"), BridgeFeedback),
    (ENGINE_STATUS, EngineStatus),
    (ENGINE_EVENTS, EngineEvent),
    (ENGINE_CELL, CellSnapshot),
    (SYNC_TOPIC, SyncMessage),
    (sm_topic(GROUP, "located"), LocatedFrames),
)

DIALECT = "https://json-schema.org/draft/2020-12/schema"
BASE_ID = "https://dual-arm-executive.invalid/schema/"
TAG = "kind"  # the key codec writes the KIND of a tagged-union member under
VERSION = "v"  # the protocol version field every message has; wire.py says it is always 1
INDEX = "index.json"
REGENERATE = "python -m node_transport.json_schema --out schema/json"
_SCALARS: dict[Any, str] = {bool: "boolean", int: "integer", float: "number", str: "string", type(None): "null"}


def file_name(cls: type) -> str:
    return f"{cls.__name__}.schema.json"


def message_types() -> tuple[type, ...]:
    """The registered dataclasses, each once, in registry order (one type may serve several topics)."""
    return tuple(dict.fromkeys(cls for _, cls in MESSAGES))


def _docs(cls: type) -> dict[str, str]:
    """Title and description from the docstring; dataclass() invents ``Name(field: type, ...)`` when there is none."""
    doc = inspect.getdoc(cls) or ""
    if doc.startswith(f"{cls.__name__}("):
        return {"title": cls.__name__}
    return {"title": cls.__name__, "description": doc}


def _default(cls: type, name: str) -> Any:
    """The JSON of a field's default: what a receiver assumes when the key is absent."""
    f = next(f for f in dataclasses.fields(cls) if f.name == name)
    value = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
    return codec.to_primitive(value)


def _union_name(members: Sequence[type]) -> str | None:
    """The module-level alias (``Primitive``) a tagged union was declared as, to name its ``$defs`` entry."""
    wanted = set(members)
    for name, value in vars(sys.modules[members[0].__module__]).items():
        if get_origin(value) in (Union, types.UnionType) and set(get_args(value)) == wanted:
            return name
    return None


class _Builder:
    """Turns the type hints of one top-level message into schemas, collecting nested types in ``$defs``."""

    def __init__(self, root: type) -> None:
        self.root = root
        self.defs: dict[str, dict[str, Any]] = {}
        self._owners: dict[str, object] = {}

    def ref(self, name: str, owner: object, build: Callable[[], dict[str, Any]]) -> dict[str, Any]:
        """A ``$ref`` to ``name``, built once; the root message refers to itself as ``#``."""
        if owner is self.root:
            return {"$ref": "#"}
        if self._owners.setdefault(name, owner) != owner:
            raise TypeError(f"two different types are both called {name!r} in {self.root.__name__}")
        if name not in self.defs:
            self.defs[name] = {}  # placeholder: a type may refer to itself while being built
            self.defs[name] = build()
        return {"$ref": f"#/$defs/{name}"}

    def hint(self, hint: Any) -> dict[str, Any]:  # noqa: C901 - mirrors codec._converter's dispatch
        """The schema of one type hint, form by form as codec._converter decodes it."""
        if hint is Any:
            return {}
        if dataclasses.is_dataclass(hint) and isinstance(hint, type):
            return self.ref(hint.__name__, hint, lambda: self.dataclass(hint))
        if isinstance(hint, type) and issubclass(hint, enum.Enum):
            return self.ref(hint.__name__, hint, lambda: {**_docs(hint), "enum": [m.value for m in hint]})
        origin = get_origin(hint)
        if origin is Literal:
            values = list(get_args(hint))
            return {"const": values[0]} if len(values) == 1 else {"enum": values}
        if origin in (Union, types.UnionType):
            return self.union(hint)
        if origin in (list, tuple):
            args = get_args(hint)
            if origin is tuple and args and args[-1] is not Ellipsis:  # fixed length, one type per place
                n = len(args)
                return {"type": "array", "prefixItems": [self.hint(a) for a in args], "items": False, "minItems": n, "maxItems": n}
            return {"type": "array", "items": self.hint(args[0] if args else Any)}
        if origin is dict:
            return {"type": "object", "additionalProperties": self.hint((get_args(hint) or (str, Any))[1])}
        if hint is None or hint in _SCALARS:
            return {"type": _SCALARS[type(None) if hint is None else hint]}
        raise TypeError(f"codec cannot carry {hint!r}, so it has no schema")

    def union(self, hint: Any) -> dict[str, Any]:
        """A tagged union is a ``oneOf`` told apart by the tag's ``const``; other unions are ``anyOf``."""
        args = get_args(hint)
        members = [a for a in args if a is not type(None)]
        null = [{"type": "null"}] if len(members) < len(args) else []
        if codec.is_tagged_union(hint):
            def variants() -> dict[str, Any]:
                return {"oneOf": [self.variant(m) for m in members]}
            name = _union_name(members)
            body = self.ref(name, frozenset(members), variants) if name else variants()
            return {"oneOf": [body, *null]} if null else body
        schemas = [self.hint(m) for m in members] + null
        if all(list(s) == ["type"] for s in schemas):  # plain scalars: the short form
            return {"type": [s["type"] for s in schemas]}
        return {"anyOf": schemas}

    def variant(self, cls: type) -> dict[str, Any]:
        """One member of a tagged union: inside the union the tag is required (codec looks it up first)."""
        return {**self.hint(cls), "properties": {TAG: {"const": cls.KIND}}, "required": [TAG]}  # type: ignore[attr-defined]

    def dataclass(self, cls: type) -> dict[str, Any]:
        """An object with the codec's field plan: JSON keys, required fields, and no other keys."""
        properties: dict[str, Any] = {}
        kind = getattr(cls, "KIND", None)
        if isinstance(kind, str):  # decoded directly, a member may leave its tag out but not change it
            properties[TAG] = {"const": kind}
        required = []
        for plan in codec.field_plan(cls):
            if plan.key in properties:
                raise TypeError(f"{cls.__name__}.{plan.name}: JSON key {plan.key!r} is taken by the union tag")
            schema = {"const": PROTOCOL_VERSION} if plan.key == VERSION else self.hint(plan.hint)
            if plan.required:
                required.append(plan.key)
            else:
                schema = {**schema, "default": _default(cls, plan.name)}
            properties[plan.key] = schema
        out: dict[str, Any] = {**_docs(cls), "type": "object", "properties": properties}
        if required:
            out["required"] = required
        out["additionalProperties"] = False  # codec refuses a key that is not a field (see docs/json_messages.md)
        return out


def build(cls: type) -> dict[str, Any]:
    """The schema document of one top-level message type."""
    builder = _Builder(cls)
    body = builder.dataclass(cls)
    comment = (
        f"Generated from {cls.__module__}.{cls.__name__} by `{REGENERATE}`; do not edit. "
        f"The decoder also refuses messages over {codec.MAX_MESSAGE_BYTES} bytes, integers written "
        "with a fraction or exponent (1.0, 1e3), and whatever the dataclass's own checks refuse."
    )
    head = {"$schema": DIALECT, "$id": BASE_ID + file_name(cls), "title": body.pop("title")}
    if "description" in body:
        head["description"] = body.pop("description")
    defs = {"$defs": builder.defs} if builder.defs else {}
    return {**head, "$comment": comment, **body, **defs}


def index() -> dict[str, Any]:
    """Topic -> message type, and message type -> schema file, for tools that start from a topic."""
    return {
        "$comment": f"Generated by `{REGENERATE}`; do not edit. Topics are relative to the node's namespace; "
        f"{GROUP} is a robot group's name.",
        "protocol_version": PROTOCOL_VERSION,
        "topics": {topic: cls.__name__ for topic, cls in MESSAGES},
        "schemas": {cls.__name__: file_name(cls) for cls in message_types()},
    }


def _text(document: dict[str, Any]) -> str:
    return json.dumps(document, indent=2, ensure_ascii=False) + "\n"


def render() -> dict[str, str]:
    """Every file of the schema folder by name, as it should read now."""
    files = {file_name(cls): _text(build(cls)) for cls in message_types()}
    files[INDEX] = _text(index())
    return files


def _obsolete(directory: Path, expected: dict[str, str]) -> list[Path]:
    """Schema files of message types that are no longer registered."""
    return sorted(p for p in directory.glob("*.schema.json") if p.name not in expected)


def stale(directory: Path) -> list[Path]:
    """Files in ``directory`` that differ from what :func:`render` produces, are missing, or are obsolete."""
    expected = render()
    differing = [directory / name for name, text in expected.items()
                 if not (directory / name).is_file() or (directory / name).read_text(encoding="utf-8") != text]
    return differing + _obsolete(directory, expected)


def write(directory: Path) -> list[Path]:
    """Write every schema and the index into ``directory``, removing obsolete schemas; returns what changed."""
    changed = stale(directory)
    expected = render()
    directory.mkdir(parents=True, exist_ok=True)
    for path in _obsolete(directory, expected):
        path.unlink()
    for name, text in expected.items():
        (directory / name).write_text(text, encoding="utf-8")
    return changed


def main(argv: Sequence[str] | None = None) -> int:
    """``--out DIR`` writes the schemas; ``--check DIR`` exits 1 naming each stale file."""
    parser = argparse.ArgumentParser(prog="python -m node_transport.json_schema", description=__doc__.splitlines()[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--out", type=Path, metavar="DIR", help="write one <Message>.schema.json per message type and index.json")
    mode.add_argument("--check", type=Path, metavar="DIR", help="exit 1 if any file in DIR is not what --out would write")
    args = parser.parse_args(argv)
    if args.out is not None:
        for path in write(args.out):
            print(f"{'updated' if path.exists() else 'removed'} {path}")
        return 0
    problems = stale(args.check)
    for path in problems:
        print(f"stale: {path}", file=sys.stderr)
    if problems:
        print(f"regenerate with: {REGENERATE}", file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
