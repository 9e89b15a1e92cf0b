"""Offsets into every file and iteration of an expanded application, in one number each.

The checks locate everything they report by an offset into the application's text
(``draft.source.at_offset``).  Once loops and calls are expanded, one ``<param>`` stands for
many calls -- one per iteration, perhaps in another file -- and a message must name both the
place and the iteration.  So each (file, iteration) pair gets a block of offsets of its own: an
expanded call's offset is the block's base plus its offset in its file, and this map answers
``at_offset`` with that file's line and column and the iteration as the Location's context.
The checks, written for one file, work unchanged.  Block 0 is the application itself, outside
any loop, so the offsets of a file without loops are their own.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator

from execution_engine.app_model.diagnostics import Location
from execution_engine.app_model.positions import SourceMap

#: A file is at most 32 MiB (safe_xml.DEFAULT_MAX_BYTES): offsets below 2**32 leave room.
_SHIFT = 32
_MASK = (1 << _SHIFT) - 1


class ExpandedSource:
    """The offsets of an expanded application: which file, which iteration, where."""

    def __init__(self, main: SourceMap) -> None:
        self.main = main
        self.file = main.file
        self.text = main.text
        self._blocks: list[tuple[SourceMap, str]] = [(main, "")]
        self._index: dict[tuple[int, str], int] = {(id(main), ""): 0}

    def base(self, source: SourceMap, context: str) -> int:
        """The base of the block of ``source`` in iteration ``context`` (made on first use)."""
        key = (id(source), context)
        index = self._index.get(key)
        if index is None:
            index = self._index[key] = len(self._blocks)
            self._blocks.append((source, context))
        return index << _SHIFT

    @property
    def contexts(self) -> list[str]:
        """Every iteration context handed out (the outermost, "", first)."""
        return [context for _, context in self._blocks]

    def block(self, offset: int) -> tuple[SourceMap, str, int]:
        """The file, the iteration and the offset in that file of an expanded offset."""
        source, context = self._blocks[offset >> _SHIFT]
        return source, context, offset & _MASK

    def context(self, offset: int) -> str:
        return self._blocks[offset >> _SHIFT][1]

    def at_offset(self, offset: int) -> Location:
        source, context, own = self.block(offset)
        where = source.at_offset(own)
        return Location(where.file, where.line, where.col, context) if context else where

    def attribute_offset(self, tag_offset: int, name: str) -> int:
        source, _, own = self.block(tag_offset)
        return (tag_offset & ~_MASK) | source.attribute_offset(own, name)

    def attribute_at(self, tag_offset: int, name: str) -> Location:
        return self.at_offset(self.attribute_offset(tag_offset, name))

    def line_cols(self, offsets: Iterable[int]) -> Iterator[tuple[int, int]]:
        for offset in offsets:
            where = self.at_offset(offset)
            yield where.line, where.col

    def detach(self) -> None:
        for source, _ in self._blocks:
            source.detach()
