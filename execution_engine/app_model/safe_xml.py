"""Read an XML file from outside the program without letting it do anything but be parsed.

Application and cell files are written by users and passed around; a file must not be able to
expand entities ("billion laughs"), read other files or reach the network through a DTD, or
exhaust memory.  So: a size limit checked before reading, UTF-8 only (the text is needed for
columns anyway), any DOCTYPE or ENTITY declaration refused before the parser sees it, and lxml
configured to resolve nothing.  Every failure is a :class:`Diagnostic`, never an exception.

Memory follows the number of nodes more than the number of bytes: lxml spends some 150
bytes on each element and 250 on each attribute, so 31 MB of ``<x/>`` would be a gigabyte of
tree.  Elements and attributes are therefore capped (:data:`MAX_ELEMENTS`,
:data:`MAX_ATTRIBUTES`, counted in the text before the tree is built), and
comments and processing instructions are dropped while parsing -- nothing reads them, and a
file of comments was half a gigabyte of comment nodes.
"""
from __future__ import annotations

import codecs
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from lxml import etree

from execution_engine.app_model.diagnostics import Diagnostic, Location
from execution_engine.app_model.positions import SourceMap, start_tags_and_attributes

DEFAULT_MAX_BYTES = 32 * 1024 * 1024
#: Elements a file may hold: six times the 10,000-operation benchmark application, five times a
#: 200,000-frame cell (which is already too large to run); some 150 MB of tree at the limit.
MAX_ELEMENTS = 1_000_000
#: Attributes a file may hold (each costs lxml about 250 bytes: 500 MB at the limit).
MAX_ATTRIBUTES = 2_000_000

_DECLARATIONS = re.compile(r"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<!(DOCTYPE|ENTITY)", re.S)
_ENCODING = re.compile(r"""^<\?xml[^>]*?\sencoding\s*=\s*["']([^"']*)["']""")
_UTF8_NAMES = {"utf-8", "utf8", "us-ascii", "ascii"}
_LXML_POSITION = re.compile(r",\s*line \d+,\s*column \d+\s*$")

# libxml2's wording for the syntax errors people make by hand, in plain words.
_SYNTAX_REWRITES: tuple[tuple[re.Pattern[str], str], ...] = (
    (re.compile(r"Opening and ending tag mismatch: (\S+) line (\d+) and (\S+)"),
     r"closing tag </\3> does not match <\1> opened on line \2"),
    (re.compile(r"""AttValue: " or ' expected"""), "attribute value must be in quotes"),
    (re.compile(r"Premature end of data in tag (\S+) line (\d+)"), r"the file ends before <\1> (line \2) is closed"),
    (re.compile(r"EndTag: '</' not found"), "the file ends before the root element is closed"),
    (re.compile(r"Start tag expected, '<' not found"), "no XML element found"),
    (re.compile(r"Document is empty"), "the file is empty"),
    (re.compile(r"Extra content at the end of the document"), "text after the end of the root element"),
    (re.compile(r"Entity '([^']*)' not defined"), r"unknown entity &\1; (only &lt; &gt; &amp; &quot; &apos; and &#...; exist)"),
    (re.compile(r"Attribute (\S+) redefined"), r"attribute \1 is given twice"),
    (re.compile(r"Resource limit exceeded: .*|.*XML_PARSE_HUGE.*|Excessive depth in document.*"),
     "the file goes beyond the parser's limits (at most 256 levels of nesting and 10 MB for one tag, text or name)"),
)


@dataclass(frozen=True)
class XmlDocument:
    """A parsed, well-formed file: its root element and where everything is in the text.

    ``valid_against``: the schema the parser found the file valid against while reading it (None:
    not checked, or not valid -- then the structure check says why)."""

    path: Path
    root: etree._Element
    source: SourceMap
    valid_against: etree.XMLSchema | None = None

    @property
    def file(self) -> str:
        return self.source.file


def hardened_parser(schema: etree.XMLSchema | None = None) -> etree.XMLParser:
    """The parser every XML file goes through: no entities expanded, no network, no DTD, libxml2's size limits.

    With ``schema`` it also validates while parsing (libxml2's streaming validation: no second
    walk of the tree, and no node paths computed for errors) and refuses an invalid file."""
    # A new parser per file: its error log then holds this file's errors only.
    return etree.XMLParser(
        resolve_entities=False,
        no_network=True,
        load_dtd=False,
        dtd_validation=False,
        huge_tree=False,  # keeps libxml2's limits: 256 levels of nesting, 10 MB per text or name
        remove_comments=True,
        remove_pis=True,
        schema=schema,
    )


def _location_of_byte(file: str, data: bytes, offset: int) -> Location:
    before = data[:offset].decode("utf-8", errors="replace")
    line = before.count("\n") + 1
    return Location(file, line, len(before) - (before.rfind("\n") + 1) + 1)


def _decode(file: str, data: bytes) -> tuple[str | None, Diagnostic | None]:
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE, codecs.BOM_UTF32_LE, codecs.BOM_UTF32_BE)):
        return None, Diagnostic(file, 1, 1, "the file is UTF-16/32; only UTF-8 files are supported")
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8):]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        where = _location_of_byte(file, data, error.start)
        return None, Diagnostic.at(where, f"invalid UTF-8 byte 0x{data[error.start]:02x} (files must be UTF-8)")
    declared = _ENCODING.match(text)
    if declared and declared.group(1).strip().lower() not in _UTF8_NAMES:
        col = declared.start(1) + 1
        return None, Diagnostic(file, 1, col, f"encoding {declared.group(1)!r} is not supported; write the file in UTF-8")
    return text, None


def _refuse_declarations(file: str, text: str) -> Diagnostic | None:
    if "<!DOCTYPE" not in text and "<!ENTITY" not in text:
        return None
    for match in _DECLARATIONS.finditer(text):
        if match.group(1):
            where = SourceMap(file, text).at_offset(match.start())
            return Diagnostic.at(
                where,
                f"<!{match.group(1)}> declarations are not allowed "
                "(DTDs and entities are refused so a file cannot expand or fetch anything)",
            )
    return None


def _syntax_message(message: str) -> str:
    message = _LXML_POSITION.sub("", message).strip()
    for pattern, replacement in _SYNTAX_REWRITES:
        if pattern.search(message):
            return pattern.sub(replacement, message)
    return message


def read_xml(
    path: Path, *, display: str | None = None, max_bytes: int = DEFAULT_MAX_BYTES, schema: etree.XMLSchema | None = None,
) -> tuple[XmlDocument | None, list[Diagnostic]]:
    """Parse ``path`` safely; the document, or None and the reasons (``display`` names the file).
    ``schema``: validate while parsing (:func:`parse_bytes`)."""
    file = display if display is not None else str(path)
    try:
        info = os.stat(path)
    except OSError as error:
        return None, [Diagnostic(file, 1, 1, f"cannot read the file: {error.strerror or error}")]
    if not stat.S_ISREG(info.st_mode):
        return None, [Diagnostic(file, 1, 1, "not a regular file")]
    if info.st_size > max_bytes:
        return None, [Diagnostic(file, 1, 1, f"the file is {info.st_size} bytes, over the limit of {max_bytes} bytes")]
    try:
        data = _read_at_most(path, info.st_size, max_bytes)
    except OSError as error:
        return None, [Diagnostic(file, 1, 1, f"cannot read the file: {error.strerror or error}")]
    if len(data) > max_bytes:
        return None, [Diagnostic(file, 1, 1, f"the file is over the limit of {max_bytes} bytes")]
    return parse_bytes(data, path=path, display=file, schema=schema)


def _read_at_most(path: Path, size: int, max_bytes: int) -> bytes:
    """The file's bytes, reading at most ``max_bytes + 1`` (a larger result means: too large).

    ``read(max_bytes + 1)`` would allocate the whole limit for every file, however small; the
    size from ``stat`` is the first guess and a file that grew since is read on in chunks.
    """
    with open(path, "rb") as stream:
        data = stream.read(min(size, max_bytes) + 1)
        if len(data) <= size or len(data) > max_bytes:
            return data
        chunks = [data]
        total = len(data)
        while total <= max_bytes:
            chunk = stream.read(min(1 << 20, max_bytes + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
        return b"".join(chunks)


def _too_many_nodes(display: str, data: bytes, text: str) -> Diagnostic | None:
    """A diagnostic at the first start tag past :data:`MAX_ELEMENTS`, or at the one holding the
    attribute past :data:`MAX_ATTRIBUTES`; None when the file is within both.

    Every element starts with a ``<`` that is not ``</``, ``<!`` or ``<?``, and every attribute
    holds a ``=``, so most files -- a flood of comments too -- are cleared by fast byte counts;
    otherwise the start tags are scanned (comments, CDATA, instructions and end tags left out),
    stopping at the first one over a limit.
    """
    if data.count(b"=") <= MAX_ATTRIBUTES:
        opening = data.count(b"<")  # counts end tags too: usually enough to clear the file at once
        if opening <= MAX_ELEMENTS:
            return None
        # Each count is a pass over the file (two-byte ones the slowest): the end tags alone clear most
        # large files, comments and instructions are counted only when they still might not.
        opening -= data.count(b"</")
        if opening <= MAX_ELEMENTS or opening - data.count(b"<!") - data.count(b"<?") <= MAX_ELEMENTS:
            return None
    source = SourceMap(display, text)
    attributes = 0
    for index, (offset, count) in enumerate(start_tags_and_attributes(source.text)):
        attributes += count
        if index == MAX_ELEMENTS:
            what = f"{MAX_ELEMENTS:,} elements"
        elif attributes > MAX_ATTRIBUTES:
            what = f"{MAX_ATTRIBUTES:,} attributes"
        else:
            continue
        return Diagnostic.at(source.at_offset(offset), (
            f"the file has more than {what}, the limit; split it (a cell model or an application this "
            "large is a generated file gone wrong)"
        ))
    return None


def parse_bytes(
    data: bytes, *, path: Path, display: str, schema: etree.XMLSchema | None = None,
) -> tuple[XmlDocument | None, list[Diagnostic]]:
    """Parse bytes already read (and size-checked) as the content of ``path``.

    ``schema``: validate while parsing; a valid file comes back with ``valid_against`` set and
    needs no structure check.  Any other file is parsed again without the schema, so a syntax
    error is reported as one, and the structure check (bounded whatever the file) says what
    the schema refuses -- the extra parse is paid only by files with a mistake."""
    text, problem = _decode(display, data)
    if text is None:
        return None, [problem] if problem else []
    problem = _refuse_declarations(display, text) or _too_many_nodes(display, data, text)
    if problem is not None:
        return None, [problem]
    if schema is not None:
        try:
            root = etree.fromstring(data, hardened_parser(schema))
        except (etree.LxmlError, ValueError):
            pass  # not valid, or not well-formed: the plain parse below says which
        else:
            if root is not None and _no_dtd(root):
                return XmlDocument(path=path, root=root, source=SourceMap(display, text, root), valid_against=schema), []
    source = SourceMap(display, text)
    try:
        root = etree.fromstring(data, hardened_parser())
    except etree.XMLSyntaxError as error:
        line, col = error.position if error.position else (1, 1)
        return None, [Diagnostic.at(source.at_line(line or 1, col or 1), _syntax_message(str(error.msg or error)))]
    except (etree.LxmlError, ValueError) as error:
        return None, [Diagnostic(display, 1, 1, f"cannot parse the file: {error}")]
    if root is None:
        return None, [Diagnostic(display, 1, 1, "no XML element found")]
    if not _no_dtd(root):  # defence in depth
        return None, [Diagnostic(display, 1, 1, "DTDs are not allowed")]
    source.attach(root)
    return XmlDocument(path=path, root=root, source=source), []


def _no_dtd(root: etree._Element) -> bool:
    docinfo = root.getroottree().docinfo
    return not getattr(docinfo, "doctype", "") and getattr(docinfo, "internalDTD", None) is None
