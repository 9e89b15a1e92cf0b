"""Line and column of every element and attribute, computed from the source text.

lxml gives an element's ``sourceline`` -- the line where its start tag *ends*, and only
approximately beyond line 65535 -- and no column.  Diagnostics must point at the ``<tag`` or
``attr=`` at fault, so the start tags are found again in the text: once the document is known to
be well-formed, every ``<`` outside comments, CDATA and processing instructions that is not ``</``
opens an element, in document order, which is exactly the order of ``root.iter()``.  The two are
zipped once, on first use, into an element -> offset map.  Columns are 1-based and count
characters (a tab is one column).
"""
from __future__ import annotations

import bisect
import itertools
import re

from lxml import etree

from execution_engine.app_model.diagnostics import Location

# Skip comments, CDATA sections, processing instructions and end tags; capture a start tag's name.
_TAGS = re.compile(r"<(?:!--.*?-->|!\[CDATA\[.*?\]\]>|\?.*?\?>|/|([^\s/>!?][^\s/>]*))", re.S)
_ATTRIBUTE = re.compile(r"""\s+([^\s=/>]+)\s*=\s*(?:"[^"]*"|'[^']*')""")


def _qualified_name(element: etree._Element) -> str:
    tag = element.tag
    if isinstance(tag, str) and not tag.startswith("{"):
        return tag
    local = etree.QName(element).localname
    return f"{element.prefix}:{local}" if element.prefix else local


class SourceMap:
    """Locations in one file's text; element offsets are computed on first use and cached."""

    def __init__(self, file: str, text: str, root: etree._Element | None = None) -> None:
        self.file = file
        # XML reads CR LF and a lone CR as one line break; so do lines and columns here.
        self.text = text.replace("\r\n", "\n").replace("\r", "\n") if "\r" in text else text
        self._root = root
        self._line_starts: list[int] | None = None
        self._offsets: dict[etree._Element, int] | None = None

    # ---------------------------------------------------------------- offsets and lines
    def _lines(self) -> list[int]:
        if self._line_starts is None:
            lines = self.text.split("\n")
            self._line_starts = [0, *itertools.accumulate(len(line) + 1 for line in lines[:-1])]
        return self._line_starts

    def at_offset(self, offset: int) -> Location:
        starts = self._lines()
        index = bisect.bisect_right(starts, offset) - 1
        return Location(self.file, index + 1, offset - starts[index] + 1)

    def at_line(self, line: int, col: int = 1) -> Location:
        """A location lxml reported (1-based line, character column), clamped into the file."""
        starts = self._lines()
        line = min(max(line, 1), len(starts))
        end = starts[line] - 1 if line < len(starts) else len(self.text)
        return Location(self.file, line, min(max(col, 1), end - starts[line - 1] + 1))

    def _element_offsets(self) -> dict[etree._Element, int]:
        if self._offsets is None:
            self._offsets = {}
            if self._root is not None:
                starts = [(m.start(), m.group(1)) for m in _TAGS.finditer(self.text) if m.group(1)]
                elements = list(self._root.iter(etree.Element))
                # Equal counts and names mean the scan saw the parser's elements; otherwise fall
                # back to sourceline-based guesses rather than point at the wrong tag.
                if len(starts) == len(elements) and all(
                    name == _qualified_name(el) for (_, name), el in zip(starts, elements)
                ):
                    self._offsets = {el: offset for (offset, _), el in zip(starts, elements)}
        return self._offsets

    def element_offset(self, element: etree._Element) -> int | None:
        return self._element_offsets().get(element)

    # ---------------------------------------------------------------- public look-ups
    def element(self, element: etree._Element) -> Location:
        """Where ``<tag`` of ``element`` starts."""
        offset = self.element_offset(element)
        if offset is not None:
            return self.at_offset(offset)
        return self._guess(element, "<" + _qualified_name(element))

    def attribute(self, element: etree._Element, name: str) -> Location:
        """Where ``name=`` starts in the start tag of ``element`` (the tag itself if absent)."""
        offset = self.element_offset(element)
        if offset is None:
            return self._guess(element, name + "=")
        pos = offset + 1 + len(_qualified_name(element))
        while True:
            match = _ATTRIBUTE.match(self.text, pos)
            if match is None:
                return self.at_offset(offset)
            if match.group(1) == name:
                return self.at_offset(match.start(1))
            pos = match.end()

    def _guess(self, element: etree._Element, needle: str) -> Location:
        line = element.sourceline or 1
        starts = self._lines()
        line = min(max(line, 1), len(starts))
        end = starts[line] if line < len(starts) else len(self.text)
        found = self.text.find(needle, starts[line - 1], end)
        return Location(self.file, line, found - starts[line - 1] + 1 if found >= 0 else 1)
