"""A :class:`~operator_station.blocks.BlockDocument` read from an application file and written back, through lxml.

Reading goes first through :func:`execution_engine.app_model.safe_xml.parse_bytes` (the hardened
parser: size and element limits, no entities, DTDs or network), then walks the same bytes again
keeping comments, as :func:`execution_engine.app_model.document.parse_document` does.

Writing builds the element tree with lxml and indents it two spaces a level: what comes out is
equal to what was read in canonical XML (C14N 2.0, whitespace between elements set aside:
:func:`canonical`), never byte for byte (quotes, empty elements and line breaks are lxml's), and
it expands to the same operations.

Each written line is mapped to the step (its path in the tree), group and param it belongs to
(:class:`Where`), so a validator message at ``FILE:LINE:COL`` is shown at its row and cell.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import NamedTuple

from lxml import etree

from execution_engine.app_model.diagnostics import Diagnostic
from execution_engine.app_model.document import POLICY_ATTRIBUTES, AppDocument, CallEntry, DocumentError, OperationEntry, ParamEntry
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, parse_bytes
from operator_station.blocks import BLOCK_KINDS, Block, BlockDocument, OperationStep, Step

#: The root's attributes the document holds, in the order written.
ROOT_ATTRIBUTES = ("name", "robot", "cell", "version", "sync")
#: Read again after the hardened parser accepted the bytes: the same settings, comments kept.
_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False, remove_pis=True)
#: The declaration the shipped files open with (lxml's own has single quotes).
DECLARATION = b'<?xml version="1.0" encoding="UTF-8"?>\n'
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*\Z")


class Where(NamedTuple):
    """What a written line belongs to: a step (its path: indexes from the top body down), a group's
    call, a param; ``step`` None for the application's own lines."""

    step: tuple[int, ...] | None = None
    group: str | None = None
    param: int | None = None
    part: str = "application"


# ------------------------------------------------------------------------------ reading
def parse_blocks(data: bytes, path: Path | str, *, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[BlockDocument | None, list[Diagnostic]]:
    """The block document of an application file's bytes, or None and why it cannot be read.

    Lenient beyond the XML itself, as ``parse_document``: what the schema would refuse is kept or
    skipped so the builder can show the file and the validator say what is wrong."""
    path = Path(path)
    if len(data) > max_bytes:
        return None, [Diagnostic(str(path), 1, 1, f"the file is {len(data)} bytes, over the limit of {max_bytes} bytes")]
    checked, problems = parse_bytes(data, path=path, display=str(path))  # the limits, refusals and syntax errors
    if checked is None:
        return None, problems
    root = etree.fromstring(data, _PARSER)  # the same document again, with its comments
    if root.tag != "application":
        return None, [Diagnostic(str(path), 1, 1, f"the root element is <{root.tag}>, not <application>")]
    unheld: list[str] = []
    _attributes(root, (*ROOT_ATTRIBUTES, "{http://www.w3.org/2001/XMLSchema-instance}noNamespaceSchemaLocation"), unheld)
    head = AppDocument(root.get("name", ""), root.get("robot", ""), root.get("cell"), root.get("version"),
                       header=[str(c.text or "") for c in root.itersiblings(preceding=True) if c.tag is etree.Comment][::-1])
    description, policy = root.find("description"), root.find("error_policy")
    if description is not None:
        head.description = description.text or ""
    if policy is not None:
        head.error_policy = {str(k): str(v) for k, v in policy.attrib.items()}
    body, head.trailer = _body(root, unheld, top=True)
    return BlockDocument(head, body, root.get("sync"), unheld), []


def read_blocks(path: Path | str, *, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[BlockDocument | None, list[Diagnostic]]:
    """The file's block document; its size is looked at before it is read (parse_blocks checks what was read)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        data = path.read_bytes() if size <= max_bytes else b""
    except OSError as error:
        return None, [Diagnostic(str(path), 1, 1, f"cannot read the file: {error.strerror or error}")]
    if size > max_bytes:
        return None, [Diagnostic(str(path), 1, 1, f"the file is {size} bytes, over the limit of {max_bytes} bytes")]
    return parse_blocks(data, path, max_bytes=max_bytes)


def _attributes(element: etree._Element, known: tuple[str, ...], unheld: list[str]) -> None:
    for name in element.attrib:
        if name not in known:
            unheld.append(f"attribute {name} of <{element.tag}> at line {element.sourceline}")


def _body(parent: etree._Element, unheld: list[str], *, top: bool = False) -> tuple[list[Step], list[str]]:
    """The steps of a body and the comments after its last step."""
    steps: list[Step] = []
    pending: list[str] = []
    for child in parent:
        if child.tag is etree.Comment:
            pending.append(str(child.text or ""))
        elif not isinstance(child.tag, str):
            continue
        elif child.tag == "operation":
            steps.append(_operation(child, pending, unheld))
            pending = []
        elif child.tag in BLOCK_KINDS:
            steps.append(_block(child, pending, unheld))
            pending = []
        elif not (top and child.tag in ("description", "error_policy")):
            unheld.append(f"<{child.tag}> at line {child.sourceline}")
    return steps, pending


def _children(element: etree._Element, unheld: list[str]) -> list[etree._Element]:
    """The child elements; a comment among them is something the model does not hold."""
    out = []
    for child in element:
        if child.tag is etree.Comment:
            unheld.append(f"a comment inside <{element.tag}> at line {child.sourceline}")
        elif isinstance(child.tag, str):
            out.append(child)
    return out


def _operation(element: etree._Element, comments: list[str], unheld: list[str]) -> OperationStep:
    _attributes(element, ("id", "name", "break"), unheld)
    operation = OperationStep(element.get("id", ""), element.get("name"), comments=list(comments), breakpoint=element.get("break") == "true")
    pending: list[str] = []
    for group in element:
        if group.tag is etree.Comment:  # above a group's call, or after the last one
            pending.append(str(group.text or ""))
            continue
        if not isinstance(group.tag, str):
            continue
        if pending:
            operation.inner[group.tag], pending = pending, []
        functions = _children(group, unheld)
        if len(functions) != 1 or functions[0].tag != "function":
            unheld.append(f"<{group.tag}> at line {group.sourceline} without one <function>")
            continue
        function = functions[0]
        _attributes(function, ("name",), unheld)
        holders = _children(function, unheld)
        if len(holders) > 1 or any(h.tag != "params" for h in holders):
            unheld.append(f"<function> at line {function.sourceline} holding more than one <params>")
        params = []
        for param in (_children(holders[0], unheld) if holders else []):
            _attributes(param, ("value", "name"), unheld)
            params.append(ParamEntry(param.get("value", ""), param.get("name")))
        operation.calls.append(CallEntry(group.tag, function.get("name", ""), params))
    if pending:
        operation.inner[""] = pending
    return operation


def _block(element: etree._Element, comments: list[str], unheld: list[str]) -> Block:
    kind = BLOCK_KINDS[str(element.tag)]
    _attributes(element, kind.attributes, unheld)
    block = Block(kind.tag, {name: element.get(name, "") for name in kind.attributes if element.get(name) is not None}, comments=list(comments))
    if kind.params:
        for param in _children(element, unheld):
            if param.tag != "param":
                unheld.append(f"<{param.tag}> inside <call> at line {param.sourceline}")
                continue
            _attributes(param, ("name", "value"), unheld)
            block.params.append(ParamEntry(param.get("value", ""), param.get("name", "")))
    else:
        block.body, block.trailer = _body(element, unheld)
    return block


# ------------------------------------------------------------------------------ writing
def _comment(text: str, where: str) -> etree._Comment:
    # a comment cannot hold "--" nor end with "-", and keeps no carriage return (XML reads line ends as "\n")
    safe = text.replace("\r\n", "\n").replace("\r", "\n").replace("--", "- -")
    try:
        return etree.Comment(safe[:-1] + "- " if safe.endswith("-") else safe)
    except ValueError:
        raise DocumentError(f"{where}: a comment holds a character XML cannot carry") from None


def _set(element: etree._Element, name: str, value: str | None, where: str) -> None:
    if value is None:
        return
    try:
        element.set(name, value)
    except ValueError:
        raise DocumentError(f"{where}: {name} holds a character XML cannot carry") from None


def write_blocks(document: BlockDocument) -> tuple[str, list[Where]]:
    """The XML (two-space indented, through lxml) and, for each of its lines, what the line belongs to.

    DocumentError (one line naming the step) for what XML cannot carry: a group that is not a
    name, a control character in a value."""
    head = document.head
    root = etree.Element("application")
    for name, value in zip(ROOT_ATTRIBUTES, (head.name, head.robot, head.cell, head.version, document.sync)):
        _set(root, name, value, "application")
    placed: dict[etree._Element, Where] = {root: Where()}
    if head.description is not None:
        description = etree.SubElement(root, "description")
        try:
            description.text = head.description
        except ValueError:
            raise DocumentError("application: the description holds a character XML cannot carry") from None
        placed[description] = Where(part="description")
    if head.error_policy is not None:
        policy = etree.SubElement(root, "error_policy")
        for name in POLICY_ATTRIBUTES:
            _set(policy, name, head.error_policy.get(name), "error_policy")
        placed[policy] = Where(part="error_policy")
    _write_body(root, document.body, (), placed)
    for text in head.trailer:
        root.append(_comment(text, "application"))
    etree.indent(root, space="  ")
    above = b"".join(etree.tostring(_comment(text, "application"), encoding="UTF-8") + b"\n" for text in head.header)  # each on its own lines
    data = DECLARATION + above + etree.tostring(root, encoding="UTF-8") + b"\n"
    return data.decode("utf-8"), _line_map(root, data, placed)


def _write_body(parent: etree._Element, body: list[Step], path: tuple[int, ...], placed: dict[etree._Element, Where]) -> None:
    for index, step in enumerate(body):
        here = (*path, index)
        where = f"step {'.'.join(str(i + 1) for i in here)}"
        for text in step.comments:
            parent.append(_comment(text, where))
        if isinstance(step, OperationEntry):
            _write_operation(parent, step, here, where, placed)
            continue
        element = etree.SubElement(parent, step.kind)
        placed[element] = Where(here, part=step.kind)
        for name, value in step.attributes.items():
            _set(element, name, value, where)
        for i, param in enumerate(step.params):
            holder = etree.SubElement(element, "param")
            _set(holder, "name", param.name, where)
            _set(holder, "value", param.value, where)
            placed[holder] = Where(here, None, i, "param")
        _write_body(element, step.body, here, placed)
        for text in step.trailer:
            element.append(_comment(text, where))


def _write_operation(parent: etree._Element, operation: OperationEntry, here: tuple[int, ...], where: str, placed: dict[etree._Element, Where]) -> None:
    element = etree.SubElement(parent, "operation")
    _set(element, "id", operation.id, where)
    _set(element, "name", operation.name, where)
    if operation.breakpoint:  # the builder's toggle on the operation's block
        _set(element, "break", "true", where)
    placed[element] = Where(here, part="operation")
    inner: dict[str, list[str]] = getattr(operation, "inner", {})
    for call in operation.calls:
        if not _NAME.match(call.group):
            raise DocumentError(f"{where}: group {call.group!r} is not a name")
        for text in inner.get(call.group, ()):
            element.append(_comment(text, where))
        group = etree.SubElement(element, call.group)
        function = etree.SubElement(group, "function")
        _set(function, "name", call.function, where)
        placed[group] = Where(here, call.group, part="call")
        placed[function] = Where(here, call.group, part="function")
        if call.params:
            holder = etree.SubElement(function, "params")
            placed[holder] = Where(here, call.group, part="function")
            for i, param in enumerate(call.params):
                item = etree.SubElement(holder, "param")
                _set(item, "name", param.name, where)
                _set(item, "value", param.value, where)
                placed[item] = Where(here, call.group, i, "param")
    called = {call.group for call in operation.calls}
    for group, texts in inner.items():  # after the last call, and those of a group no longer called
        if group not in called:
            for text in texts:
                element.append(_comment(text, where))


def _line_map(root: etree._Element, data: bytes, placed: dict[etree._Element, Where]) -> list[Where]:
    """Each line's owner: the element that starts on it, else the one started last before it."""
    again = etree.fromstring(data, _PARSER)
    starts: dict[int, Where] = {}
    for built, read in zip(root.iter(), again.iter()):
        owner = placed.get(built)
        if owner is not None and read.sourceline not in starts:
            starts[read.sourceline] = owner
    lines, current = [], Where()
    for line in range(1, data.count(b"\n") + 2):
        current = starts.get(line, current)
        lines.append(current)
    return lines


def canonical(data: bytes) -> bytes:
    """C14N 2.0 of an application's bytes, comments kept, whitespace around elements set aside:
    what the builder's save keeps of a file."""
    root = etree.fromstring(data, _PARSER)
    return etree.tostring(root.getroottree(), method="c14n2", with_comments=True, strip_text=True)

