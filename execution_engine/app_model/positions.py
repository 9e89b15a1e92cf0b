"""Line and column of every element and attribute, computed from the source text.

lxml gives an element's ``sourceline`` -- the line where its start tag *ends*, and only
approximately beyond line 65535 -- and no column.  Diagnostics must point at the ``<tag`` or
``attr=`` at fault, so the start tags are found again in the text: once the document is known to
be well-formed, every ``<`` outside comments, CDATA and processing instructions that is not ``</``
opens an element, in document order, which is exactly the order of ``root.iter()``.

Positions travel as character offsets (cheap to keep for 10^5 elements) and become a
:class:`Location` only when a diagnostic or the final model needs one.  Columns are 1-based and
count characters (a tab is one column); CR LF and a lone CR count as one line break, as in XML.

Memory is kept to a few bytes per element and per line (arrays of offsets, one string per
distinct tag name): a file at the size limit holds a million of each.
"""
from __future__ import annotations

import bisect
import re
from array import array
from collections.abc import Iterable, Iterator

from lxml import etree

from execution_engine.app_model.diagnostics import Location

# Skip comments, CDATA sections, processing instructions and end tags; capture a start tag's name.
_TAGS = re.compile(r"<(?:!--.*?-->|!\[CDATA\[.*?\]\]>|\?.*?\?>|/|([^\s/>!?][^\s/>]*))", re.S)
# Without comments, CDATA or processing instructions every "<" that is not "</" opens an element.
_PLAIN_TAGS = re.compile(r"<([^\s/>!?][^\s/>]*)")
_PLAIN_STARTS = re.compile(r"<(?=[^\s/>!?])")  # the same, offsets only (no name to copy out)
_TAG_NAME = re.compile(r"<[^\s/>]+")
_ATTRIBUTE = re.compile(r"""\s+([^\s=/>]+)\s*=\s*(?:"[^"]*"|'[^']*')""")
_NEWLINE = re.compile("\n")


def _tag_matches(text: str) -> Iterator[re.Match[str]]:
    """The start tags of a well-formed text, in document order, one match each (name: group 1)."""
    body = text[text.find("?>") + 2:] if text.startswith("<?xml") else text
    if "<!--" in body or "<![CDATA[" in body or "<?" in body:
        return (m for m in _TAGS.finditer(text) if m.group(1))
    return _PLAIN_TAGS.finditer(text)


def start_tags_and_attributes(text: str) -> Iterator[tuple[int, int]]:
    """(offset, number of attributes) of each start tag, lazily, so a count can stop at a limit.

    Attributes are matched one at a time from the tag name on: one regex repeating a group over a
    tag of millions of attributes would keep a backtracking record of each (gigabytes)."""
    for match in _tag_matches(text):
        head = _TAG_NAME.match(text, match.start())
        count = 0
        position = head.end() if head is not None else match.end()
        attribute = _ATTRIBUTE.match(text, position)
        while attribute is not None:
            count += 1
            attribute = _ATTRIBUTE.match(text, attribute.end())
        yield match.start(), count


def qualified_name(element: etree._Element) -> str:
    """The element's name as written in the text (``prefix:local`` for namespaced elements)."""
    tag = element.tag
    if isinstance(tag, str) and not tag.startswith("{"):
        return tag
    local = etree.QName(element).localname
    return f"{element.prefix}:{local}" if element.prefix else local


class SourceMap:
    """Offsets and locations in one file's text."""

    def __init__(self, file: str, text: str, root: etree._Element | None = None) -> None:
        self.file = file
        self.text = text.replace("\r\n", "\n").replace("\r", "\n") if "\r" in text else text
        self._root = root
        self._line_starts: array[int] | None = None
        self._starts: array[int] | None = None
        self._tags: tuple[array[int], list[str]] | None = None
        self._offsets: dict[etree._Element, int] | None = None
        self._located: dict[etree._Element, int] = {}

    def attach(self, root: etree._Element) -> None:
        """The tree parsed from this text, whose elements the map locates."""
        self._root = root

    def detach(self) -> None:
        """Let the tree go once its elements have become offsets: a reader's drafts keep none, and
        the tree is most of a large file's memory.  Offsets, lines and columns keep working."""
        self._root = None
        self._offsets = None
        self._located = {}

    # ---------------------------------------------------------------- lines
    def _lines(self) -> array[int]:
        if self._line_starts is None:
            starts = array("q", [0])
            starts.extend(m.end() for m in _NEWLINE.finditer(self.text))
            self._line_starts = starts
        return self._line_starts

    def line_col(self, offset: int) -> tuple[int, int]:
        starts = self._lines()
        index = bisect.bisect_right(starts, offset) - 1
        return index + 1, offset - starts[index] + 1

    def line_cols(self, offsets: Iterable[int]) -> Iterator[tuple[int, int]]:
        """``line_col`` of each offset, counting the line breaks between one and the next.

        For the offsets of a whole model, in document order as a reader finds them: a few short
        counts each instead of the table of every line start (built only if an offset goes back)."""
        text, line, line_start, last = self.text, 1, 0, 0
        count, rfind = text.count, text.rfind
        for offset in offsets:
            if offset < last:
                yield self.line_col(offset)
                continue
            breaks = count("\n", last, offset)
            if breaks:
                line += breaks
                line_start = rfind("\n", last, offset) + 1
            last = offset
            yield line, offset - line_start + 1

    def at_offset(self, offset: int) -> Location:
        if self._line_starts is None and offset < 65536:  # near the top (a root's attribute): no table of every line
            line = self.text.count("\n", 0, offset) + 1
            return Location(self.file, line, offset - (self.text.rfind("\n", 0, offset) + 1) + 1)
        line, col = self.line_col(offset)
        return Location(self.file, line, col)

    def at_line(self, line: int, col: int = 1) -> Location:
        """A location lxml reported (1-based line, character column), clamped into the file."""
        starts = self._lines()
        line = min(max(line, 1), len(starts))
        end = starts[line] - 1 if line < len(starts) else len(self.text)
        return Location(self.file, line, min(max(col, 1), end - starts[line - 1] + 1))

    # ---------------------------------------------------------------- start tags
    def tag_offsets(self) -> array[int]:
        """Offsets of every start tag, in document order (computed once)."""
        if self._starts is None:
            text = self.text
            body = text[text.find("?>") + 2:] if text.startswith("<?xml") else text
            if "<!--" in body or "<![CDATA[" in body or "<?" in body:
                self._starts = array("q", [m.start() for m in _tag_matches(text)])
            else:
                self._starts = array("q", map(re.Match.start, _PLAIN_STARTS.finditer(text)))
        return self._starts

    def start_tags(self) -> tuple[array[int], list[str]]:
        """Offsets and names of every start tag, in document order (computed once).

        The names are shared: one string per distinct tag, not one per element."""
        if self._tags is None:
            raw = [m.group(1) for m in _tag_matches(self.text)]
            shared: dict[str, str] = {}
            self._tags = self.tag_offsets(), list(map(shared.setdefault, raw, raw))
        return self._tags

    def _element_offsets(self) -> dict[etree._Element, int]:
        """Every element's offset, by zipping the scan with ``root.iter()`` (built only when needed)."""
        if self._offsets is None:
            self._offsets = {}
            if self._root is not None:
                offsets, names = self.start_tags()
                elements = list(self._root.iter(etree.Element))
                # Equal names mean the scan saw the parser's elements; otherwise fall back to
                # sourceline-based guesses rather than point at the wrong tag.
                if len(names) == len(elements) and all(n == qualified_name(e) for n, e in zip(names, elements)):
                    self._offsets = dict(zip(elements, offsets))
        return self._offsets

    def locate(self, elements: Iterable[etree._Element]) -> None:
        """Find the offsets of a few elements in one walk of the tree, without the map of all.

        The map (:meth:`_element_offsets`) holds a Python object per element; for the handful of
        elements a report points at, counting them off in document order is enough.
        """
        wanted = {e for e in elements if e not in self._located}
        if not wanted or self._root is None or self._offsets is not None:
            return
        offsets, names = self.start_tags()
        for index, element in enumerate(self._root.iter(etree.Element)):
            if element in wanted:
                if index >= len(names) or names[index] != qualified_name(element):
                    return  # the scan disagrees with the parser: element_offset falls back
                self._located[element] = offsets[index]
                wanted.discard(element)
                if not wanted:
                    return

    def element_offset(self, element: etree._Element) -> int:
        """Offset of ``<tag`` of ``element`` (a best guess on its source line if the scan disagrees)."""
        offset = self._located.get(element)
        if offset is None:
            offset = self._element_offsets().get(element)
        if offset is not None:
            return offset
        starts = self._lines()
        sourceline = element.sourceline
        line = min(max(sourceline if isinstance(sourceline, int) else 1, 1), len(starts))
        end = starts[line] if line < len(starts) else len(self.text)
        found = self.text.find("<" + qualified_name(element), starts[line - 1], end)
        return found if found >= 0 else starts[line - 1]

    def attribute_offset(self, tag_offset: int, name: str) -> int:
        """Offset of ``name=`` in the start tag at ``tag_offset`` (the tag itself if it is absent)."""
        head = _TAG_NAME.match(self.text, tag_offset)
        if head is None:
            return tag_offset
        pos = head.end()
        while True:
            match = _ATTRIBUTE.match(self.text, pos)
            if match is None:
                return tag_offset
            if match.group(1) == name:
                return match.start(1)
            pos = match.end()

    # ---------------------------------------------------------------- locations
    def element(self, element: etree._Element) -> Location:
        """Where ``<tag`` of ``element`` starts."""
        return self.at_offset(self.element_offset(element))

    def attribute(self, element: etree._Element, name: str) -> Location:
        """Where ``name=`` starts in the start tag of ``element`` (the tag itself if absent)."""
        return self.at_offset(self.attribute_offset(self.element_offset(element), name))

    def attribute_at(self, tag_offset: int, name: str) -> Location:
        return self.at_offset(self.attribute_offset(tag_offset, name))


class DocumentWalk:
    """Hands out element offsets to a reader that visits elements in document order.

    A reader that walks the tree top-down and visits every element (skipping a subtree calls
    :meth:`skip`) sees them in the order of the scan, so the n-th visit gets the n-th start tag
    without a map from elements to offsets -- the map costs a third of loading a large file.
    Each visit checks that the text there is ``<`` and the element's name; after any
    disagreement the walk falls back to the map.  A hot loop may do the same inline with
    ``offsets``, ``text`` and ``next`` (:meth:`at` for one element).
    """

    def __init__(self, source: SourceMap) -> None:
        self.source = source
        self.text = source.text
        self.offsets = source.tag_offsets()
        self.next = 0
        self.aligned = True

    def visit(self, element: etree._Element) -> int:
        index = self.next
        self.next = index + 1
        return self.at(index, element)

    def at(self, index: int, element: etree._Element) -> int:
        """The offset of ``element``, the ``index``-th element in document order.

        The check is that the text there begins with ``<`` and the element's name: the scan finds
        exactly the start tags of a well-formed text, so it is a guard, not a search.  A
        namespaced element (``{uri}name`` against ``p:name``) fails it and takes the map."""
        if self.aligned and index < len(self.offsets):
            offset = self.offsets[index]
            if self.text.startswith(element.tag, offset + 1):  # type: ignore[arg-type]
                return offset
        self.aligned = False
        return self.source.element_offset(element)

    def skip(self, element: etree._Element) -> None:
        """``element``'s subtree is not read: step over it (``element`` itself was visited)."""
        if len(element):
            self.next += sum(1 for _ in element.iter(etree.Element)) - 1
