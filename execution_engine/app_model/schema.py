"""Structural validation against the XSDs, with libxml2's messages rewritten into plain words.

The schema says *what may go where*; libxml2 says so in terms of content models and facets
("[facet 'pattern'] The value '1a' is not accepted by the pattern ..."). Users need the element,
the attribute and what would be accepted, at the right line and column.  The wording of a value
error comes from the ``xs:documentation`` of the simple type in the XSD itself, so the schema
stays the single description of every attribute.
"""
from __future__ import annotations

import copy
import difflib
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from lxml import etree

from execution_engine.app_model.diagnostics import Diagnostic, Location
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, XmlDocument, read_xml
from execution_engine.resources import share_path

XS = "{http://www.w3.org/2001/XMLSchema}"

_BUILTIN_TYPES = {
    "xs:string": "a text",
    "xs:double": "a number",
    "xs:decimal": "a number",
    "xs:integer": "a whole number",
    "xs:nonNegativeInteger": "a whole number, 0 or more",
}

# Extra advice for an element found where the schema does not allow it: (parent, element) -> hint.
_PLACEMENT_HINTS = {
    ("application", "description"): "<description> and <error_policy> come before the first <operation>, at most once each",
    ("application", "error_policy"): "<description> and <error_policy> come before the first <operation>, at most once each",
    ("function", "param"): "params go inside <params>",
}
_GROUP_HINT = "a group runs exactly one <function> per operation; put the next one in a new <operation>"

_ELEMENT_MSG = re.compile(r"^Element '([^']*)'(?:, attribute '([^']*)')?: (.*)$", re.S)
_EXPECTED = re.compile(r"Expected is(?: one of)? \( ([^)]*) \)")


@dataclass(frozen=True)
class SchemaInfo:
    """A compiled XSD and what the message rewriting needs to know about it."""

    name: str
    schema: etree.XMLSchema
    root: str  # the element a document must start with
    attributes: dict[str, dict[str, str]] = field(default_factory=dict)  # element -> attribute -> type
    children: dict[str, tuple[str, ...]] = field(default_factory=dict)  # element -> allowed child elements
    type_docs: dict[str, str] = field(default_factory=dict)  # simple type -> what it accepts, in words


def _child_elements(complex_type: etree._Element) -> tuple[str, ...]:
    """Names of the elements a complex type's content model allows (not those of grandchildren)."""
    names: list[str] = []
    stack = list(complex_type)
    while stack:
        node = stack.pop(0)
        if node.tag == f"{XS}element":
            names.append(node.get("name", ""))
        elif node.tag in (f"{XS}sequence", f"{XS}choice", f"{XS}all"):
            stack[:0] = list(node)
    return tuple(names)


def _describe(name: str, xsd: etree._Element, schema: etree.XMLSchema) -> SchemaInfo:
    """What each element may hold, and the words for each simple type, read off the XSD itself."""
    types = {t.get("name", ""): t for t in xsd.iterfind(f"{XS}complexType")}
    docs: dict[str, str] = {}
    for simple in xsd.iterfind(f"{XS}simpleType"):
        text = simple.findtext(f"{XS}annotation/{XS}documentation")
        if text:
            docs[simple.get("name", "")] = " ".join(text.split())
    attributes: dict[str, dict[str, str]] = {}
    children: dict[str, tuple[str, ...]] = {}
    for element in xsd.iter(f"{XS}element"):
        element_name = element.get("name")
        complex_type = element.find(f"{XS}complexType")
        if complex_type is None:
            complex_type = types.get(element.get("type", ""))
        if not element_name or complex_type is None:
            continue
        children[element_name] = _child_elements(complex_type)
        own = attributes.setdefault(element_name, {})
        for attribute in complex_type.iterfind(f"{XS}attribute"):
            own[attribute.get("name", "")] = attribute.get("type", "xs:string")
    root = next((e.get("name", "") for e in xsd.iterfind(f"{XS}element")), "")
    return SchemaInfo(name=name, schema=schema, root=root, attributes=attributes, children=children, type_docs=docs)


@lru_cache(maxsize=None)
def load_schema(name: str) -> SchemaInfo:
    """The compiled ``apps_xml/schema/<name>.xsd`` (our own trusted file, parsed once)."""
    path: Path = share_path("apps_xml", "schema", f"{name}.xsd")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    xsd = etree.parse(str(path), parser)
    return _describe(name, xsd.getroot(), etree.XMLSchema(xsd))


class _PathIndex:
    """Resolves libxml2's node paths (``/application/operation[3]/left_arm``) in linear total time."""

    def __init__(self, root: etree._Element) -> None:
        self._root = root
        self._children: dict[etree._Element, dict[str, list[etree._Element]]] = {}

    def find(self, path: str | None) -> etree._Element | None:
        if not path or not path.startswith("/"):
            return None
        steps = path.strip("/").split("/")
        match = re.fullmatch(r"([^\[\]]+)(?:\[(\d+)\])?", steps[0])
        if match is None or match.group(1) != self._root.tag:
            return None
        node = self._root
        for step in steps[1:]:
            match = re.fullmatch(r"([^\[\]]+)(?:\[(\d+)\])?", step)
            if match is None:
                return None
            by_tag = self._children.get(node)
            if by_tag is None:
                by_tag = {}
                for child in node.iterchildren(etree.Element):
                    by_tag.setdefault(child.tag, []).append(child)
                self._children[node] = by_tag
            candidates = by_tag.get(match.group(1), [])
            index = int(match.group(2) or 1) - 1
            if not 0 <= index < len(candidates):
                return None
            node = candidates[index]
        return node


def _names(listing: str) -> list[str]:
    return [n.strip() for n in listing.split(",") if n.strip()]


def _one_of(names: list[str]) -> str:
    tags = [f"<{n}>" for n in names]
    return tags[0] if len(tags) == 1 else ", ".join(tags[:-1]) + " or " + tags[-1]


class _Rewriter:
    def __init__(self, info: SchemaInfo) -> None:
        self.info = info

    def expected_value(self, element: str, attribute: str) -> str:
        type_name = self.info.attributes.get(element, {}).get(attribute, "")
        return self.info.type_docs.get(type_name) or _BUILTIN_TYPES.get(type_name, "a valid value")

    def attribute_message(self, node: etree._Element | None, element: str, attribute: str, detail: str) -> str:
        if "is not allowed" in detail:
            allowed = sorted(self.info.attributes.get(element, {}))
            close = difflib.get_close_matches(attribute, allowed, n=1)
            hint = f" (did you mean {close[0]}?)" if close else ""
            return f"<{element}> has no attribute {attribute}{hint}; it takes: {', '.join(allowed)}"
        value = node.get(attribute) if node is not None else None
        shown = f"={value!r}" if value is not None else ""
        return f"attribute {attribute}{shown} of <{element}>: expected {self.expected_value(element, attribute)}"

    def element_message(self, node: etree._Element | None, element: str, detail: str) -> str:
        parent = node.getparent() if node is not None else None
        parent_tag = parent.tag if parent is not None and isinstance(parent.tag, str) else ""
        required = re.match(r"The attribute '([^']*)' is required but missing", detail)
        if required:
            return f"<{element}> needs the attribute {required.group(1)}"
        expected = _EXPECTED.search(detail)
        expected_names = _names(expected.group(1)) if expected else []
        if detail.startswith("Missing child element"):
            if "operation" in expected_names:
                return f"<{element}> needs at least one <operation>"
            return f"<{element}> needs {_one_of(expected_names)} inside"
        if detail.startswith("This element is not expected"):
            return self._unexpected(element, parent_tag, expected_names)
        if detail.startswith("Element content is not allowed"):
            return f"<{element}> holds text only, no elements"
        if detail.startswith("Character content is not allowed"):
            return f"<{element}> cannot contain text; write values as attributes"
        if detail.startswith("Character content other than whitespace"):
            return f"text is not allowed inside <{element}>, only elements"
        if "No matching global declaration" in detail:
            return f"the root element is <{element}>; this file must start with <{self.info.root}>"
        return f"<{element}>: {detail.strip()}"

    def _unexpected(self, element: str, parent: str, expected: list[str]) -> str:
        where = f" inside <{parent}>" if parent else ""
        message = f"<{element}> is not allowed here{where}"
        hint = _PLACEMENT_HINTS.get((parent, element))
        if hint is None and element == "function" and parent in {"left_arm", "right_arm", "torso_head", "arm"}:
            hint = _GROUP_HINT
        if hint is None and element not in self.info.attributes:
            candidates = expected or list(self.info.attributes)
            close = difflib.get_close_matches(element, candidates, n=1)
            if close:
                hint = f"did you mean <{close[0]}>?"
        allowed = self.info.children.get(parent, ())
        if not expected and element not in allowed:
            expected = list(allowed)
        if expected:
            message += f"; expected {_one_of(expected)}"
        return message + (f" ({hint})" if hint else "")


MAX_PASSES = 20


def validate_structure(doc: XmlDocument, schema: str) -> list[Diagnostic]:
    """Every schema violation of ``doc``, one diagnostic per element or attribute at fault.

    libxml2 stops checking a parent's remaining children at the first element it did not expect,
    which would hide every later mistake in that operation.  So the unexpected elements are taken
    out of a copy of the tree and the copy is checked again, until nothing new turns up (at most
    MAX_PASSES times); problems are always reported on the original elements.
    """
    info = load_schema(schema)
    if info.schema.validate(doc.root):
        return []
    rewriter = _Rewriter(info)
    out: list[Diagnostic] = []
    reported: set[tuple[object, str | None, str]] = set()
    work = doc.root
    original: dict[etree._Element, etree._Element] | None = None  # copy element -> original
    pruned: set[etree._Element] = set()  # original parents that lost a child in the copy
    for attempt in range(MAX_PASSES):
        if attempt and info.schema.validate(work):
            break
        index = _PathIndex(work)
        unexpected: list[etree._Element] = []
        entries: Iterable[etree._LogEntry] = info.schema.error_log  # type: ignore[assignment]  # iterable; stubs lag
        for entry in entries:
            found = index.find(getattr(entry, "path", None))
            node = original.get(found, found) if original is not None and found is not None else found
            match = _ELEMENT_MSG.match(entry.message or "")
            element, attribute, detail = (match.group(1), match.group(2), match.group(3)) if match else ("", None, entry.message or "")
            if detail.startswith("Missing child") and node in pruned:
                continue  # caused by taking an unexpected child out of the copy
            key = (node if node is not None else entry.line, attribute, "" if attribute is not None else detail)
            if key in reported:
                continue  # a facet error and its "not a valid value" follow-up are one problem
            reported.add(key)
            if attribute is not None:
                message = rewriter.attribute_message(node, element, attribute, detail)
            else:
                message = rewriter.element_message(node, element, detail)
            out.append(Diagnostic.at(_where(doc, node, attribute, entry.line), message))
            if detail.startswith("This element is not expected") and found is not None and found.getparent() is not None:
                unexpected.append(found)
        if not unexpected:
            break
        if original is None:
            work, original = _copy(doc.root)
            copies = {v: k for k, v in original.items()}
            unexpected = [copies[u] for u in unexpected]
        for node in unexpected:
            parent = node.getparent()
            if parent is not None:
                pruned.add(original.get(parent, parent))
                parent.remove(node)
    return out


def _copy(root: etree._Element) -> tuple[etree._Element, dict[etree._Element, etree._Element]]:
    duplicate = copy.deepcopy(root)
    return duplicate, dict(zip(duplicate.iter(), root.iter()))


def _where(doc: XmlDocument, node: etree._Element | None, attribute: str | None, line: int) -> Location:
    if node is None:
        return doc.source.at_line(line or 1)
    if attribute is not None:
        return doc.source.attribute(node, attribute)
    return doc.source.element(node)


def read_structured(path: Path, schema: str, *, display: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES) -> tuple[XmlDocument | None, list[Diagnostic]]:
    """Read ``path`` safely and check it against ``schema``: the document (None when it is unreadable
    or has the wrong root element, as then nothing more can be said) and the problems so far."""
    doc, diagnostics = read_xml(path, display=display, max_bytes=max_bytes)
    if doc is None:
        return None, diagnostics
    diagnostics = validate_structure(doc, schema)
    if doc.root.tag != load_schema(schema).root:
        return None, diagnostics
    return doc, diagnostics
