"""The application as an editable document: what an editor opens, changes and saves as XML.

The validated :class:`~execution_engine.app_model.model.Application` is normalised for the
engine (defaults filled in, left-out groups turned into waits), so it cannot be written back as
the user wrote it.  An :class:`AppDocument` keeps what the file says -- the groups an operation
names, in their order, the params as written (with their ``name=`` if any), the error policy's
attributes as written, the comment above the root and the comments between operations -- so the
operator station's builder (paper Figure 7) can open a file, let the user change it and save it.

:func:`serialize` writes the paper's Figure 6 layout (one element per line, like the shipped
rivet demonstrator): a file in that layout is saved back byte for byte, any other valid file is
saved as the same application (``load_application`` gives equal operations), and saving what
was saved changes nothing.  Every line it writes is mapped to the operation, group and param it
belongs to (:class:`Placement`), so a validator message at ``FILE:LINE:COL`` can be shown at its
cell of the builder's table.

Parsing goes through :mod:`.safe_xml` (size and element limits, no entities or DTDs); the
document is not validated here -- :func:`execution_engine.app_model.read_application` does that.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from lxml import etree

from execution_engine.app_model.diagnostics import Diagnostic
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, parse_bytes

#: The error policy's attributes in the order the schema lists them (and the serializer writes them).
POLICY_ATTRIBUTES = ("retries", "action", "safe_pose", "alarm_timeout", "safe_speed", "retreat")


@dataclass(slots=True)
class ParamEntry:
    value: str
    name: str | None = None


@dataclass(slots=True)
class CallEntry:
    """One group's function in one operation, as written."""

    group: str
    function: str
    params: list[ParamEntry] = field(default_factory=list)


@dataclass(slots=True)
class OperationEntry:
    id: str
    name: str | None = None
    calls: list[CallEntry] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)  # the comments written just above it
    breakpoint: bool = False  # break="true": the run pauses before it (engine/breakpoints.py)

    def call(self, group: str) -> CallEntry | None:
        return next((c for c in self.calls if c.group == group), None)


@dataclass
class AppDocument:
    name: str
    robot: str
    cell: str | None = None
    version: str | None = None
    description: str | None = None
    error_policy: dict[str, str] | None = None
    operations: list[OperationEntry] = field(default_factory=list)
    header: list[str] = field(default_factory=list)  # comments above the root element
    trailer: list[str] = field(default_factory=list)  # comments after the last operation
    #: The loops and calls of the file (``<for_each> at line 12``), which this document does not hold:
    #: the builder shows the operations written at the top only, and must not save over the file.
    steps: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """Plain dicts and lists (``asdict`` without its deep copies: a 10,000-operation file in a tenth of the time)."""
        return {
            "name": self.name, "robot": self.robot, "cell": self.cell, "version": self.version, "description": self.description,
            "error_policy": None if self.error_policy is None else dict(self.error_policy),
            "operations": [{
                "id": op.id, "name": op.name, "comments": list(op.comments),
                "calls": [{"group": c.group, "function": c.function, "params": [{"value": p.value, "name": p.name} for p in c.params]} for c in op.calls],
                **({"break": True} if op.breakpoint else {}),
            } for op in self.operations],
            "header": list(self.header), "trailer": list(self.trailer), "steps": list(self.steps),
        }

    @staticmethod
    def from_json(data: Any) -> AppDocument:
        """The document a client sent; a :class:`DocumentError` names the first field that is wrong."""
        if not isinstance(data, dict):
            raise DocumentError("the application must be a JSON object")
        policy = data.get("error_policy")
        if policy is not None and not (isinstance(policy, dict) and all(k in POLICY_ATTRIBUTES and isinstance(v, str) for k, v in policy.items())):
            raise DocumentError(f"error_policy: attributes are {', '.join(POLICY_ATTRIBUTES)} with text values")
        operations = data.get("operations")
        if not isinstance(operations, list):
            raise DocumentError("operations: a list is needed")
        return AppDocument(
            name=_text(data, "name", "application"),
            robot=_text(data, "robot", "application"),
            cell=_optional(data, "cell", "application"),
            version=_optional(data, "version", "application"),
            description=_optional(data, "description", "application"),
            error_policy=None if policy is None else dict(policy),
            operations=[_operation(op, i) for i, op in enumerate(operations, start=1)],
            header=_texts(data, "header", "application"),
            trailer=_texts(data, "trailer", "application"),
        )


class DocumentError(ValueError):
    """A document sent by a client does not have the shape of an application."""


def _text(data: dict[str, Any], key: str, where: str) -> str:
    value = data.get(key)
    if not isinstance(value, str):
        raise DocumentError(f"{where}: {key} must be text")
    return value


def _optional(data: dict[str, Any], key: str, where: str) -> str | None:
    value = data.get(key)
    if value is not None and not isinstance(value, str):
        raise DocumentError(f"{where}: {key} must be text or null")
    return value


def _texts(data: dict[str, Any], key: str, where: str) -> list[str]:
    value = data.get(key) or []
    if not (isinstance(value, list) and all(isinstance(v, str) for v in value)):
        raise DocumentError(f"{where}: {key} must be a list of texts")
    return list(value)


def _operation(data: Any, index: int) -> OperationEntry:
    """One operation of a client's document; checked inline (a 10,000-operation document goes through here per edit)."""
    if not isinstance(data, dict) or not isinstance(data.get("calls"), list):
        raise DocumentError(f"operation {index}: an object with calls is needed")
    calls = []
    for call in data["calls"]:
        group, function, params = (call.get("group"), call.get("function"), call.get("params", [])) if isinstance(call, dict) else (None, None, None)
        if not (isinstance(group, str) and isinstance(function, str) and isinstance(params, list)):
            raise DocumentError(f"operation {index}: each call needs group, function and params")
        entries = []
        for p in params:
            value, name = (p.get("value"), p.get("name")) if isinstance(p, dict) else (None, None)
            if not isinstance(value, str) or not (name is None or isinstance(name, str)):
                raise DocumentError(f"operation {index}: each param needs a text value (and a text name or none)")
            entries.append(ParamEntry(value, name))
        calls.append(CallEntry(group, function, entries))
    where = f"operation {index}"
    breakpoint = data.get("break", False)
    if not isinstance(breakpoint, bool):
        raise DocumentError(f"{where}: break must be true or false")
    return OperationEntry(_text(data, "id", where), _optional(data, "name", where), calls, _texts(data, "comments", where), breakpoint)


# ------------------------------------------------------------------------------ reading
def parse_document(data: bytes, path: Path | str, *, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[AppDocument | None, list[Diagnostic]]:
    """The document of an application file's bytes, or None and why it cannot be read.

    Lenient beyond the XML itself: what the schema would reject (a missing name, an unknown
    element) is kept or skipped so the builder can show the file and the validator say what is wrong.
    """
    path = Path(path)
    if len(data) > max_bytes:
        return None, [Diagnostic(str(path), 1, 1, f"the file is {len(data)} bytes, over the limit of {max_bytes} bytes")]
    doc, problems = parse_bytes(data, path=path, display=str(path))  # the limits, refusals and syntax errors
    if doc is None:
        return None, problems
    root = etree.fromstring(data, _COMMENT_KEEPING_PARSER)  # the same document again, with its comments
    if root.tag != "application":
        return None, [Diagnostic(str(path), 1, 1, f"the root element is <{root.tag}>, not <application>")]
    document = AppDocument(
        name=root.get("name", ""), robot=root.get("robot", ""), cell=root.get("cell"), version=root.get("version"),
        header=[_comment(c) for c in root.itersiblings(preceding=True) if isinstance(c, etree._Comment)][::-1],
    )
    pending: list[str] = []
    for child in root:
        if isinstance(child, etree._Comment):
            pending.append(_comment(child))
        elif child.tag == "description":
            document.description = child.text or ""
        elif child.tag == "error_policy":
            document.error_policy = {k: str(v) for k, v in child.attrib.items()}
        elif child.tag == "operation":
            document.operations.append(_read_operation(child, pending))
            pending = []
        elif child.tag in ("for_each", "repeat", "call"):
            document.steps.append(f"<{child.tag}> at line {child.sourceline}")
    document.trailer = pending
    return document, []


#: As :mod:`.safe_xml`'s parser (no entities, network or DTDs, libxml2's limits) but keeping comments.
_COMMENT_KEEPING_PARSER = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False, remove_pis=True)


def _comment(node: etree._Comment) -> str:
    return str(node.text or "")


def _read_operation(element: etree._Element, comments: list[str]) -> OperationEntry:
    operation = OperationEntry(id=element.get("id", ""), name=element.get("name"), comments=list(comments), breakpoint=element.get("break") == "true")
    for group in element:
        if not isinstance(group.tag, str):
            continue
        function = group.find("function")
        if function is None:
            operation.calls.append(CallEntry(group.tag, ""))
            continue
        params = [ParamEntry(p.get("value", ""), p.get("name")) for p in function.iterfind("params/param")]
        operation.calls.append(CallEntry(group.tag, function.get("name", ""), params))
    return operation


def read_document(path: Path | str, *, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[AppDocument | None, list[Diagnostic]]:
    path = Path(path)
    try:
        with open(path, "rb") as stream:
            data = stream.read(max_bytes + 1)
    except OSError as error:
        return None, [Diagnostic(str(path), 1, 1, f"cannot read the file: {error.strerror or error}")]
    return parse_document(data, path, max_bytes=max_bytes)


# ------------------------------------------------------------------------------ writing
class Placement(NamedTuple):
    """What a written line belongs to: the application (operation None), an operation, a group's call, a param.

    A tuple, not a dataclass: a 10,000-operation application writes 150,000 lines, each with one."""

    operation: int | None = None  # index into AppDocument.operations
    group: str | None = None
    param: int | None = None
    part: str = "application"  # application, description, error_policy, operation, call, function, param


#: Attribute escapes in one pass (str.translate): markup, and the whitespace XML would otherwise normalise.
_COMMON = {ord("&"): "&amp;", ord("<"): "&lt;", ord(">"): "&gt;", ord("\n"): "&#10;", ord("\t"): "&#9;", ord("\r"): "&#13;"}
_ESCAPES = {"'": str.maketrans({**_COMMON, ord("'"): "&apos;"}), '"': str.maketrans({**_COMMON, ord('"'): "&quot;"})}


def _attr(value: str, quote: str) -> str:
    return quote + value.translate(_ESCAPES[quote]) + quote


def _escape_text(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _comment_lines(text: str, indent: str) -> list[str]:
    safe = text.replace("--", "- -")  # a comment cannot hold "--"
    return [f"{indent}<!--{safe.rstrip('-') if safe.endswith('-') else safe}-->"]


def serialize(document: AppDocument) -> tuple[str, list[Placement]]:
    """The XML text (Figure 6 layout) and, for each of its lines, what the line belongs to."""
    lines: list[str] = []
    where: list[Placement] = []

    def emit(text: str, placement: Placement) -> None:
        if "\n" in text:  # a comment or description over several lines: one placement per line
            for line in text.split("\n"):
                lines.append(line)
                where.append(placement)
        else:
            lines.append(text)
            where.append(placement)

    top = Placement()
    emit('<?xml version="1.0" encoding="UTF-8"?>', top)
    for comment in document.header:
        emit(_comment_lines(comment, "")[0], top)
    attributes = [("name", document.name), ("robot", document.robot), ("cell", document.cell), ("version", document.version)]
    emit("<application" + "".join(f" {k}={_attr(v, chr(34))}" for k, v in attributes if v is not None) + ">", top)
    if document.description is not None:
        emit(f"  <description>{_escape_text(document.description)}</description>", Placement(part="description"))
    if document.error_policy is not None:
        ordered = [k for k in POLICY_ATTRIBUTES if k in document.error_policy]
        emit("  <error_policy" + "".join(f" {k}={_attr(document.error_policy[k], chr(34))}" for k in ordered) + "/>", Placement(part="error_policy"))
    for index, operation in enumerate(document.operations):
        at_operation = Placement(index, part="operation")
        for comment in operation.comments:
            emit(_comment_lines(comment, "  ")[0], at_operation)
        name = f" name={_attr(operation.name, chr(39))}" if operation.name is not None else ""
        stop = " break='true'" if operation.breakpoint else ""
        emit(f"  <operation id={_attr(operation.id, chr(39))}{name}{stop}>", at_operation)
        for call in operation.calls:
            at_call, at_function = Placement(index, call.group, part="call"), Placement(index, call.group, part="function")
            lines.append(f"    <{call.group}>")
            where.append(at_call)
            function = _attr(call.function, chr(39))
            if not call.params:
                lines.append(f"      <function name={function}></function>")
                where.append(at_function)
            else:
                lines.append(f"      <function name={function}>")
                lines.append("        <params>")
                where.extend((at_function, at_function))
                for i, param in enumerate(call.params):
                    named = f"name={_attr(param.name, chr(39))} " if param.name is not None else ""
                    emit(f"          <param {named}value={_attr(param.value, chr(39))}></param>", Placement(index, call.group, i, "param"))
                lines.append("        </params>")
                lines.append("      </function>")
                where.extend((at_function, at_function))
            lines.append(f"    </{call.group}>")
            where.append(at_call)
        lines.append("  </operation>")
        where.append(at_operation)
    for comment in document.trailer:
        emit(_comment_lines(comment, "  ")[0], top)
    emit("</application>", top)
    return "\n".join(lines) + "\n", where


def to_xml(document: AppDocument) -> str:
    return serialize(document)[0]
