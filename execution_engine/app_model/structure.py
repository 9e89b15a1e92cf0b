"""Check a document against its XSD in time linear in its size, whatever the file holds.

libxml2 reports each schema error with the node's path (``/cell/frame[4711]/actual``), which lxml
computes at once by counting the node's preceding siblings at every level.  A sibling list of n
elements with an error each therefore costs n²/2 steps: 40,000 frames with a bad name took 17 s,
a million would take hours.  And libxml2 stops checking a parent's children at the first one it
did not expect, so every later mistake there needs another pass.

So no document handed to libxml2 has a sibling list longer than :data:`WINDOW`:

* the children of every element with more than ``WINDOW`` of them are taken out first, and the
  rest of the tree is checked as it stands (those elements hollow, their "missing child" errors
  ignored);
* each such element's children are then checked ``WINDOW`` at a time, moved under a scaffold --
  shallow copies of the element and its ancestors -- so each window is checked in its context.
  A window after the first starts with a copy of the last allowed child before it, so a content
  model that is a sequence (a second ``<function>``, ``<description>`` after the operations) says
  the same as it would for the whole list; errors of copies are ignored, those of the element
  itself counted once (its "missing child" only in its last window).

Every error then costs at most ``WINDOW`` steps per level.  Unexpected elements are taken out of
the document checked and it is checked again (at most :data:`MAX_PASSES` times per document),
all siblings of an unknown tag at once, so a flood of unknown elements costs one pass.  Every
change is undone before this module returns; the caller's tree is as it was.  Problems beyond
the report's limit are counted, not described (:class:`DiagnosticLog`).
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path

from lxml import etree

from execution_engine.app_model.diagnostics import Diagnostic, DiagnosticLog, Location
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, XmlDocument, parse_bytes, read_xml
from execution_engine.app_model.schema import ELEMENT_MESSAGE, PathIndex, Rewriter, SchemaInfo, load_schema

#: The longest sibling list libxml2 is given; longer ones are checked in windows of this size.
WINDOW = 64
#: Passes per document checked (each takes out the elements found unexpected by the one before).
MAX_PASSES = 20
_NOT_EXPECTED = "This element is not expected"
_MISSING = "Missing child"
_NO_DECLARATION = "No matching global declaration"


@dataclass(frozen=True)
class _Problem:
    """One schema problem, located once the tree is whole again."""

    node: etree._Element | None
    attribute: str | None
    line: int
    message: str


@dataclass
class _Document:
    """What one libxml2 run checks: a root, and how its nodes relate to the real tree."""

    root: etree._Element
    copies: dict[etree._Element, etree._Element]  # scaffold copy -> the original it stands for
    stubs: frozenset[etree._Element] = frozenset()  # stand-ins for the sequence state: ignored
    owner: etree._Element | None = None  # the copy whose real children are in this window
    last_window: bool = True


class StructureCheck:
    """One check of one document; :meth:`run` returns the problems, the tree unchanged."""

    def __init__(self, doc: XmlDocument, info: SchemaInfo, log: DiagnosticLog) -> None:
        self.doc = doc
        self.info = info
        self.log = log
        self.rewriter = Rewriter(info)
        self.problems: list[_Problem] = []
        self.hollow: set[etree._Element] = set()
        self.owner_reported: set[tuple[object, str | None, str]] = set()  # across the windows of one element
        self.taken_out: set[etree._Element] = set()  # found unexpected: their content is not checked

    # ------------------------------------------------------------------ the whole tree
    def run(self) -> list[Diagnostic]:
        """The kept problems of the whole document, located; beyond the log's room, only counted."""
        root = self.doc.root
        wide = [e for e in root.iter(etree.Element) if len(e) > WINDOW]
        chains = {w: [*reversed(list(w.iterancestors())), w] for w in wide}  # before anything moves
        saved: dict[etree._Element, list[etree._Element]] = {}
        try:
            for element in wide:
                saved[element] = list(element)
                for child in saved[element]:
                    element.remove(child)
            self.hollow = set(wide)
            self.taken_out |= self.check(_Document(root, {}))
            if root.tag == self.info.root:  # otherwise nothing below the root means anything
                for element in wide:  # in document order: an element's windows after its parent's
                    if not any(a in self.taken_out for a in chains[element]):  # as libxml2: no content check there
                        self.check_windows(chains[element], saved[element])
        finally:
            for element, children in saved.items():
                element.extend(children)
        return self.located()

    def check_windows(self, chain: list[etree._Element], children: list[etree._Element]) -> None:
        """The children of ``chain[-1]``, ``WINDOW`` at a time, under copies of ``chain``."""
        copies: dict[etree._Element, etree._Element] = {}
        parent_copy: etree._Element | None = None
        for original in chain:
            duplicate = etree.Element(original.tag, dict(original.attrib))
            if parent_copy is not None:
                parent_copy.append(duplicate)
            copies[duplicate] = original
            parent_copy = duplicate
        assert parent_copy is not None
        scaffold_root = next(iter(copies))
        allowed = set(self.info.children.get(str(chain[-1].tag), ()))
        last_allowed: etree._Element | None = None
        for start in range(0, len(children), WINDOW):
            window = children[start:start + WINDOW]
            stubs: list[etree._Element] = []
            if last_allowed is not None:
                stubs.append(etree.SubElement(parent_copy, last_allowed.tag, dict(last_allowed.attrib)))
            parent_copy.extend(window)
            try:
                taken_out = self.check(_Document(scaffold_root, copies, frozenset(stubs), parent_copy, start + WINDOW >= len(children)))
            finally:
                for node in list(parent_copy):
                    parent_copy.remove(node)
            self.taken_out |= taken_out
            for child in window:  # the sequence goes on from the last child it accepted
                if isinstance(child.tag, str) and child.tag in allowed and child not in taken_out:
                    last_allowed = child

    # ------------------------------------------------------------------ one document
    def check(self, document: _Document) -> set[etree._Element]:
        """Check ``document`` until nothing new turns up; undo every pruning afterwards.  The
        elements found unexpected (and taken out while checking)."""
        schema = self.info.schema
        reported: set[tuple[object, str | None, str]] = set()
        pruned_parents: set[etree._Element] = set()
        removed: list[tuple[etree._Element, etree._Element, etree._Element | None]] = []
        try:
            for _ in range(MAX_PASSES):
                if schema.validate(document.root):
                    break
                unexpected = self.read_log(document, PathIndex(document.root), reported, pruned_parents)
                if not unexpected:
                    break
                for node in unexpected:
                    parent = node.getparent()
                    if parent is None:
                        continue
                    removed.append((parent, node, node.getnext()))
                    pruned_parents.add(document.copies.get(parent, parent))
                    parent.remove(node)
        finally:
            for parent, node, anchor in reversed(removed):
                if anchor is not None:
                    anchor.addprevious(node)
                else:
                    parent.append(node)
        return {node for _, node, _ in removed}

    def read_log(
        self, document: _Document, index: PathIndex, reported: set[tuple[object, str | None, str]], pruned: set[etree._Element],
    ) -> list[etree._Element]:
        """Record the problems of the last run; the elements to take out before the next one."""
        unexpected: dict[etree._Element, None] = {}
        entries: Iterable[etree._LogEntry] = self.info.schema.error_log  # type: ignore[assignment]  # iterable; stubs lag
        for entry in entries:
            found = index.find(getattr(entry, "path", None))
            match = ELEMENT_MESSAGE.match(entry.message or "")
            element, attribute, detail = (match.group(1), match.group(2), match.group(3)) if match else ("", None, entry.message or "")
            if self.ignored(document, found, attribute, detail):
                continue
            node = document.copies.get(found, found) if found is not None else None
            if detail.startswith(_MISSING) and node in pruned:
                continue  # caused by taking an unexpected child out
            key = (node if node is not None else entry.line, attribute, "" if attribute is not None else detail)
            seen = self.owner_reported if found is not None and found is document.owner else reported
            if key in seen:
                continue  # a facet error and its "not a valid value" follow-up are one problem
            seen.add(key)
            if attribute is not None:
                self.add(node, attribute, entry.line, partial(self.rewriter.attribute_message, node, element, attribute, detail))
            else:
                self.add(node, None, entry.line, partial(self.rewriter.element_message, node, element, detail))
            if detail.startswith(_NOT_EXPECTED) and found is not None and found.getparent() is not None:
                unexpected[found] = None
                self.unknown_siblings(document, found, reported, unexpected)
        return list(unexpected)

    def ignored(self, document: _Document, found: etree._Element | None, attribute: str | None, detail: str) -> bool:
        """Errors of stand-ins, and errors of the real tree that another document reports."""
        if found is None:
            return False
        if found in document.stubs:
            return True
        if found in document.copies:
            if found is not document.owner or attribute is not None or detail.startswith((_NOT_EXPECTED, _NO_DECLARATION)):
                return True  # a scaffold copy: the original is checked where it stands
            return detail.startswith(_MISSING) and not document.last_window  # later windows may hold it
        return found in self.hollow and detail.startswith(_MISSING)  # its children are checked in its windows

    def unknown_siblings(
        self, document: _Document, found: etree._Element, reported: set[tuple[object, str | None, str]], unexpected: dict[etree._Element, None],
    ) -> None:
        """Every sibling of an unexpected element whose tag its parent never allows, at once.

        libxml2 names one unexpected element per parent and pass; a flood of unknown elements
        would need a pass each.  The list is at most ``WINDOW`` long.
        """
        parent = found.getparent()
        if parent is None:
            return
        parent_tag = str(parent.tag)
        allowed = self.info.children.get(parent_tag)
        if allowed is None or found.tag in allowed:
            return
        for sibling in parent.iterchildren(etree.Element):
            if sibling is found or sibling in unexpected or sibling in document.stubs or sibling.tag in allowed:
                continue
            key = (sibling, None, _NOT_EXPECTED)
            if key in reported:
                continue
            reported.add(key)
            unexpected[sibling] = None
            self.add(sibling, None, sibling.sourceline or 0, partial(self.rewriter.unexpected, str(sibling.tag), parent_tag, []))

    # ------------------------------------------------------------------ results
    def add(self, node: etree._Element | None, attribute: str | None, line: int, message: Callable[[], str]) -> None:
        """Keep the problem, or only count it once the report is full (its words cost work)."""
        if len(self.problems) >= self.log.keep - len(self.log):
            self.log.count()
            return
        self.problems.append(_Problem(node, attribute, line, message()))

    def located(self) -> list[Diagnostic]:
        """The kept problems as diagnostics, now that every element is back in its place."""
        source = self.doc.source
        source.locate(p.node for p in self.problems if p.node is not None)
        return [Diagnostic.at(self.where(p), p.message) for p in self.problems]

    def where(self, problem: _Problem) -> Location:
        if problem.node is None:
            return self.doc.source.at_line(problem.line or 1)
        if problem.attribute is not None:
            return self.doc.source.attribute(problem.node, problem.attribute)
        return self.doc.source.element(problem.node)


def validate_structure(doc: XmlDocument, schema: str | SchemaInfo, log: DiagnosticLog | None = None) -> DiagnosticLog:
    """Every schema violation of ``doc``, one diagnostic per element or attribute at fault, in
    ``log`` (a new one when None): the first ones described, the rest counted.  ``schema``: a name
    under apps_xml/schema, or a schema made for the document (a cell's groups added)."""
    log = log if log is not None else DiagnosticLog()
    info = load_schema(schema) if isinstance(schema, str) else schema
    if doc.valid_against is not info.schema:  # the parser found it valid already: nothing to say
        log.extend(StructureCheck(doc, info, log).run())
    return log


def read_structured(
    path: Path, schema: str, *, display: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES, data: bytes | None = None,
) -> tuple[XmlDocument | None, DiagnosticLog]:
    """Read ``path`` safely and check it against ``schema``: the document (None when it is unreadable
    or has the wrong root element, as then nothing more can be said) and the problems so far.
    ``data``: the file's content not yet saved (an editor's), read as if it were at ``path``."""
    log = DiagnosticLog()
    compiled = load_schema(schema).schema  # validated while parsing: one pass for the files that are valid
    if not isinstance(compiled, etree.XMLSchema):
        compiled = None  # a stand-in for libxml2's check (the tests' recorder): the structure check runs it
    if data is None:
        doc, diagnostics = read_xml(path, display=display, max_bytes=max_bytes, schema=compiled)
    elif len(data) > max_bytes:
        doc, diagnostics = None, [Diagnostic(display or str(path), 1, 1, f"the file is {len(data)} bytes, over the limit of {max_bytes} bytes")]
    else:
        doc, diagnostics = parse_bytes(data, path=path, display=display or str(path), schema=compiled)
    if doc is None:
        log.extend(diagnostics)
        return None, log
    validate_structure(doc, schema, log)
    if doc.root.tag != load_schema(schema).root:
        return None, log
    return doc, log
