"""Structural validation against the XSDs, with libxml2's messages rewritten into plain words.

The schema says *what may go where*; libxml2 says so in terms of content models and facets
("[facet 'pattern'] The value '1a' is not accepted by the pattern ..."). Users need the element,
the attribute and what would be accepted, at the right line and column.  The wording of a value
error comes from the ``xs:documentation`` of the simple type in the XSD itself, so the schema
stays the single description of every attribute.  Running the check itself, in bounded time
whatever the file, is :mod:`execution_engine.app_model.structure`.
"""
from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from lxml import etree

from core_functions.resources import share_path

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
#: What may come after the head of an application, which libxml2 does not list once an unbounded choice has begun.
_STEPS = ["operation", "for_each", "repeat", "call"]
_GROUP_HINT = "a group runs exactly one <function> per operation; put the next one in a new <operation>"

ELEMENT_MESSAGE = re.compile(r"^Element '([^']*)'(?:, attribute '([^']*)')?: (.*)$", re.S)
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


@lru_cache(maxsize=16)
def application_schema_with(groups: frozenset[str]) -> SchemaInfo:
    """application.xsd whose operations also take ``groups`` as group elements: the groups a cell of
    several robots names for its robots (``viper_arm``), which no fixed list of tags can know.  The
    schema names every robot model's own groups; a cell's are added to that list, so its operations
    are checked element by element as any other's."""
    path: Path = share_path("apps_xml", "schema", "application.xsd")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    xsd = etree.parse(str(path), parser)
    operation = xsd.getroot().find(f"{XS}complexType[@name='operation']/{XS}choice")
    if operation is None:
        raise LookupError("application.xsd: no <xs:choice> of groups in complexType operation")
    known = {e.get("name") for e in operation.iterfind(f"{XS}element")}
    for group in sorted(groups - known):
        etree.SubElement(operation, f"{XS}element", name=group, type="group")
    return _describe("application", xsd.getroot(), etree.XMLSchema(xsd))


class PathIndex:
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


class Rewriter:
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
            if attribute == "break" and element != "operation":  # a breakpoint holds before one operation, not a block of them
                hint = " (a breakpoint goes on an <operation>: break=\"true\" on the first operation inside)"
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
            return self.unexpected(element, parent_tag, expected_names)
        if detail.startswith("Element content is not allowed"):
            return f"<{element}> holds text only, no elements"
        if detail.startswith("Character content is not allowed"):
            return f"<{element}> cannot contain text; write values as attributes"
        if detail.startswith("Character content other than whitespace"):
            return f"text is not allowed inside <{element}>, only elements"
        if "No matching global declaration" in detail:
            return f"the root element is <{element}>; this file must start with <{self.info.root}>"
        return f"<{element}>: {detail.strip()}"

    def unexpected(self, element: str, parent: str, expected: list[str]) -> str:
        """``<element>`` where its parent does not allow it, with what would be allowed."""
        where = f" inside <{parent}>" if parent else ""
        message = f"<{element}> is not allowed here{where}"
        hint = _PLACEMENT_HINTS.get((parent, element))
        if hint is None and element == "function" and self.info.children.get(parent) == ("function",):  # a group (a cell's own too)
            hint = _GROUP_HINT
        allowed = self.info.children.get(parent, ())
        if element not in allowed and allowed:
            # Never allowed in this parent: the answer is what the parent takes, wherever the
            # element stands (libxml2's list depends on the position it stopped at).
            expected = list(allowed)
        if hint is None and element not in self.info.attributes:
            candidates = expected or list(self.info.attributes)
            close = difflib.get_close_matches(element, candidates, n=1)
            if close:
                hint = f"did you mean <{close[0]}>?"
        if not expected and element not in allowed:
            expected = list(allowed)
        if not expected and parent == "application":
            expected = list(_STEPS)
        if expected:
            message += f"; expected {_one_of(expected)}"
        return message + (f" ({hint})" if hint else "")
