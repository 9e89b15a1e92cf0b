"""The builder's application as blocks: operations, and the loops and calls around them (issue 24).

:class:`~execution_engine.app_model.document.AppDocument` holds a flat list of operations; a file
of ``<for_each>``, ``<repeat>`` and ``<call>`` is a tree, which the page shows as nested blocks.
A :class:`BlockDocument` is that tree as written -- each block's attributes as text (``in`` as
written, never expanded: the page edits the file, not its iterations), a call's params, the
comments above each step, above each group's call and at the end of each body -- so opening and saving a looped file
gives the same XML (equal in canonical form, :mod:`operator_station.blocks_xml`).

The kinds of block are data (:data:`BLOCK_KINDS`): a branch (``<if>``, and the ``<else>`` after
it) is one more kind with its attributes and a body, not a new code path through the page and the server.

What the model does not hold (an element it does not know, a comment inside a call's params) is
listed in :attr:`BlockDocument.unheld`: the builder shows the rest and refuses to write over it.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from dataclasses import dataclass, field, replace
from typing import Any, Union

from execution_engine.app_model.document import AppDocument, DocumentError, OperationEntry, ParamEntry


@dataclass(frozen=True)
class BlockKind:
    """One kind of block: its element, its attributes in the order written, which are required,
    whether it has params (a call) and a body of steps (a loop)."""

    tag: str
    attributes: tuple[str, ...]
    required: tuple[str, ...]
    params: bool = False
    body: bool = True


#: The blocks the builder holds, as application.xsd defines them.
BLOCK_KINDS: dict[str, BlockKind] = {
    "for_each": BlockKind("for_each", ("var", "in", "index"), ("var", "in")),
    "repeat": BlockKind("repeat", ("count", "var"), ("count",)),
    "call": BlockKind("call", ("application",), ("application",), params=True, body=False),
    # an outcome branch: its steps run when the group's function in that operation ended with the outcome;
    # the <else> right after it holds the steps run otherwise (docs/application_xml.md, "Outcome branches")
    "if": BlockKind("if", ("group", "operation", "outcome"), ("group", "operation", "outcome")),
    "else": BlockKind("else", (), ()),
}
#: Blocks inside each other the page may send (the validator refuses past its own limit, 8, at the line).
MAX_NESTING = 16
#: AppDocument's message about one operation of the list it was given.
_NUMBERED = re.compile(r"operation (\d+): (.*)\Z", re.S)
#: Steps (operations and blocks) a document may hold: the validator's limit on what a file expands to.
MAX_STEPS = 100_000


@dataclass
class Block:
    kind: str
    attributes: dict[str, str] = field(default_factory=dict)
    body: list[Step] = field(default_factory=list)
    params: list[ParamEntry] = field(default_factory=list)  # a call's <param name= value=>, each with a name
    comments: list[str] = field(default_factory=list)  # the comments written just above it
    trailer: list[str] = field(default_factory=list)  # the comments after the last step of its body


@dataclass(slots=True)
class OperationStep(OperationEntry):
    """An operation with the comments written inside it: above each group's call, by group (``""``: after the
    last call) -- AppDocument's writer has no place for them, so an operation holding any is written through lxml."""

    inner: dict[str, list[str]] = field(default_factory=dict)


Step = Union[OperationEntry, Block]


@dataclass
class BlockDocument:
    """The application's head (name, robot, cell, description, error policy, comments around the
    root; its ``operations`` unused), ``sync`` as written, and the body of steps."""

    head: AppDocument
    body: list[Step] = field(default_factory=list)
    sync: str | None = None
    #: What the file holds that this document does not (``<if> at line 12``): never written over.
    unheld: list[str] = field(default_factory=list)

    def is_flat(self) -> bool:
        """Operations only, as AppDocument holds them: written in the paper's Figure 6 layout."""
        return self.sync is None and not self.unheld and all(isinstance(step, OperationEntry) and not getattr(step, "inner", None) for step in self.body)

    def flat(self) -> AppDocument:
        head = self.head
        return AppDocument(head.name, head.robot, head.cell, head.version, head.description, head.error_policy,
                           [s for s in self.body if isinstance(s, OperationEntry)], list(head.header), list(head.trailer))

    def operations(self) -> list[OperationEntry]:
        """Every operation written, in document order (inside blocks too)."""
        out: list[OperationEntry] = []
        walk(self.body, lambda step, path: out.append(step) if isinstance(step, OperationEntry) else None)
        return out

    def to_json(self) -> dict[str, Any]:
        """A flat file's JSON is AppDocument's (``operations``); any other has ``body``, a tree of steps."""
        if self.is_flat():
            return self.flat().to_json()
        out = self.head.to_json()
        del out["operations"]
        out.update(sync=self.sync, body=[_step_json(step) for step in self.body], unheld=list(self.unheld))
        return out

    @staticmethod
    def from_json(data: Any) -> BlockDocument:
        """The page's document: ``body`` (a tree of steps) or, as before blocks, ``operations``.

        Everything is checked for its shape here (DocumentError, one line naming the step); the
        ``unheld`` a page sends is ignored: what a file holds is read from the file."""
        if not isinstance(data, dict):
            raise DocumentError("the application must be a JSON object")
        if "body" not in data:
            flat = AppDocument.from_json(data)
            return BlockDocument(replace(flat, operations=[]), list(flat.operations))
        body = data.get("body")
        if not isinstance(body, list):
            raise DocumentError("body: a list of steps is needed")
        sync = data.get("sync")
        if sync not in (None, "operation", "flags"):
            raise DocumentError("application: sync must be operation, flags or null")
        head = AppDocument.from_json({**data, "operations": []})
        counter = [0]
        return BlockDocument(head, _steps(body, "step", 1, counter), sync)


def walk(body: list[Step], visit: Callable[[Step, tuple[int, ...]], object], path: tuple[int, ...] = ()) -> None:
    """Calls ``visit(step, path)`` on every step of a body, depth first in document order."""
    for index, step in enumerate(body):
        here = (*path, index)
        visit(step, here)
        if isinstance(step, Block):
            walk(step.body, visit, here)


def calls_inside(resolve: Callable[[str], object], path: Path, document: BlockDocument) -> None:
    """Every file the document's calls name passes ``resolve`` (the station's folders), as the files the page opens and
    saves: validating a call reads the called file (ValueError, one line naming the step)."""

    def visit(step: Step, where: tuple[int, ...]) -> None:
        application = step.attributes.get("application", "").strip() if isinstance(step, Block) and step.kind == "call" else ""
        if application:
            try:
                resolve(str(path.parent / application))
            except ValueError as error:
                raise ValueError(f"step {'.'.join(str(i + 1) for i in where)}: call of {error}") from None

    walk(document.body, visit)


def _step_json(step: Step) -> dict[str, Any]:
    if isinstance(step, OperationEntry):
        out = {"type": "operation", "id": step.id, "name": step.name, "comments": list(step.comments),
               "calls": [{"group": c.group, "function": c.function, "params": [{"value": p.value, "name": p.name} for p in c.params]}
                         for c in step.calls]}
        inner = getattr(step, "inner", None)
        if inner:
            out["inner"] = {group: list(texts) for group, texts in inner.items()}
        if step.breakpoint:
            out["break"] = True
        return out
    return {"type": step.kind, "attributes": dict(step.attributes), "params": [{"name": p.name, "value": p.value} for p in step.params],
            "body": [_step_json(s) for s in step.body], "comments": list(step.comments), "trailer": list(step.trailer)}


def _texts(value: Any, where: str) -> list[str]:
    if value is None:
        return []
    if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
        raise DocumentError(f"{where}: comments must be a list of texts")
    return list(value)


def _steps(data: list[Any], where: str, depth: int, counter: list[int]) -> list[Step]:
    if depth > MAX_NESTING:
        raise DocumentError(f"{where}: blocks nested more than {MAX_NESTING} deep")
    counter[0] += len(data)
    if counter[0] > MAX_STEPS:
        raise DocumentError(f"the application holds more than {MAX_STEPS:,} steps")
    label = (lambda index: f"{where} {index}") if depth == 1 else (lambda index: f"{where}.{index}")
    out: list[Step | None] = [None] * len(data)
    operations: list[int] = []  # the places of the operations: checked together, as AppDocument checks a list
    for index, item in enumerate(data):
        kind = item.get("type") if isinstance(item, dict) else None
        kind = kind if isinstance(kind, str) else None  # a list or a dict is no kind (nor a key to look one up with)
        if kind == "operation":
            operations.append(index)
        elif kind in BLOCK_KINDS:
            out[index] = _block(item, BLOCK_KINDS[kind], label(index + 1), depth, counter)
        else:
            raise DocumentError(f"{label(index + 1)}: type must be operation or one of {', '.join(BLOCK_KINDS)}")
    try:
        entries = AppDocument.from_json({"name": "", "robot": "", "operations": [data[i] for i in operations]}).operations
    except DocumentError as error:
        found = _NUMBERED.match(str(error))
        if found is None:
            raise
        raise DocumentError(f"{label(operations[int(found.group(1)) - 1] + 1)}: {found.group(2)}") from None
    for index, entry in zip(operations, entries):
        if len({c.group for c in entry.calls}) != len(entry.calls):
            raise DocumentError(f"{label(index + 1)}: a group is given twice")
        out[index] = OperationStep(entry.id, entry.name, entry.calls, entry.comments, entry.breakpoint, _inner(data[index].get("inner"), entry, label(index + 1)))
    return [step for step in out if step is not None]


def _inner(value: Any, entry: OperationEntry, where: str) -> dict[str, list[str]]:
    """An operation's inner comments; those of a group it no longer calls go after its last call."""
    if value is None:
        return {}
    if not (isinstance(value, dict) and all(isinstance(k, str) for k in value)):
        raise DocumentError(f"{where}: inner must map groups to comments")
    groups = {c.group for c in entry.calls}
    out: dict[str, list[str]] = {}
    for group, texts in value.items():
        out.setdefault(group if group in groups else "", []).extend(_texts(texts, where))
    return {group: texts for group, texts in out.items() if texts}


def _block(item: dict[str, Any], kind: BlockKind, where: str, depth: int, counter: list[int]) -> Block:
    attributes = item.get("attributes")
    if not (isinstance(attributes, dict) and all(k in kind.attributes and isinstance(v, str) for k, v in attributes.items())):
        raise DocumentError(f"{where}: <{kind.tag}> takes the attributes {', '.join(kind.attributes)}, with text values")
    missing = [name for name in kind.required if name not in attributes]
    if missing:
        raise DocumentError(f"{where}: <{kind.tag}> needs {', '.join(missing)}")
    params: list[ParamEntry] = []
    for p in item.get("params") or []:
        name, value = (p.get("name"), p.get("value")) if isinstance(p, dict) else (None, None)
        if not (kind.params and isinstance(name, str) and isinstance(value, str)):
            raise DocumentError(f"{where}: " + ("each param of a call needs a text name and value" if kind.params else f"<{kind.tag}> has no params"))
        params.append(ParamEntry(value, name))
    body = item.get("body") or []
    if not isinstance(body, list) or ((body or item.get("trailer")) and not kind.body):  # a trailer closes a body
        raise DocumentError(f"{where}: " + ("body must be a list of steps" if kind.body else f"<{kind.tag}> has no body"))
    ordered = {name: attributes[name] for name in kind.attributes if name in attributes}
    return Block(kind.tag, ordered, _steps(body, where, depth + 1, counter), params,
                 _texts(item.get("comments"), where), _texts(item.get("trailer"), where))
