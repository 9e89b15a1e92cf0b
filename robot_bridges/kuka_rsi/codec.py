"""``<Rob>`` and ``<Sen>`` packets, encoded and decoded as a configuration says.

RSI packets are small XML documents, one per 4 ms cycle.  The encoder is compiled once per
configuration into a byte template with one ``%`` slot per value, so building a reply is one
formatting call and no tree.  The decoder parses with lxml configured to resolve nothing and
refuses, before parsing, what no controller sends: oversized datagrams, DTDs, entities and
processing instructions.  Every failure is a :class:`PacketError` naming the field, so the
loop can count and report a bad datagram and carry on with the next one.

Peers differ in how they spell attribute *names*: a KR C4 sends ``<Rob Type="KUKA">``,
ROS-Industrial's ``kuka_rsi_simulator`` sends ``<Rob TYPE="KUKA">`` (Python's ElementTree, which
also sorts the attributes).  XML names are case-sensitive, but no RSI peer uses two spellings of one
name for two things, so the decoder matches attribute names of the root and of the configured
elements case-insensitively (and refuses an element that gives one name twice in two spellings);
element names and the ``Type`` value are matched exactly.  Every refusal carries a short
:attr:`PacketError.reason`, so the loop can count refusals per reason and say why a peer was refused.

Values travel in protocol units (mm, degrees); converting to SI is the caller's job.
Decoding has a fast path: a regular expression compiled from the configuration matches a packet
laid out exactly as configured (what a controller sends) in a few microseconds; its values cannot
hold markup or entities.  Anything else -- another attribute order, comments, entities in a
string -- goes through lxml, which accepts any well-formed equivalent and words the errors.

A codec owns an lxml parser, which must not be shared between threads: one codec per thread.
"""
from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from xml.sax.saxutils import escape

from lxml import etree

from robot_bridges.kuka_rsi.config import Field, RsiConfig

Value = bool | int | float | str

#: Largest datagram accepted.  Real packets are well below 1 kB; RSI itself refuses larger.
MAX_PACKET_BYTES = 4096
#: The ``Type`` attribute of every ``<Rob>`` packet.
ROB_TYPE = "KUKA"
#: The root's type attribute, as KUKA spells it (matched case-insensitively).
ROOT_ATTRIBUTE = "Type"
_MAX_IPOC = 2**63 - 1
_MAX_STRING = 256
_DOUBLE_FORMAT = "%.6f"


class PacketError(ValueError):
    """A datagram that is not a valid packet for the configuration; the message says why.

    ``reason`` is one of :data:`REASONS`: the loop counts refusals by it, the message is the example.
    """

    def __init__(self, message: str, reason: str = "value") -> None:
        super().__init__(message)
        self.reason = reason


#: Why a datagram is refused, the keys of the loop's per-reason counters.
REASONS: tuple[str, ...] = (
    "size",  # over the byte limit
    "markup",  # DTD, entity, comment, processing instruction
    "xml",  # not well-formed
    "root element",  # not <Rob> / <Sen>
    "root attribute",  # no Type attribute on the root
    "root type",  # a Type other than the expected one
    "duplicate",  # an element or an attribute given twice
    "missing",  # a configured value absent
    "value",  # a number, boolean or string that does not parse
    "ipoc",  # IPOC absent, malformed or out of range
)


def _double(raw: str, key: str) -> float:
    try:
        value = float(raw)
    except ValueError:
        raise PacketError(f"{key}={raw[:32]!r} is not a number") from None
    if not math.isfinite(value) or "_" in raw:
        raise PacketError(f"{key}={raw[:32]!r} is not a finite decimal number")
    return value


def _long(raw: str, key: str) -> int:
    text = raw.strip()
    if not text.lstrip("+-").isdigit() or len(text) > 20:
        raise PacketError(f"{key}={raw[:32]!r} is not an integer")
    return int(text)


def _ipoc(raw: str) -> int:
    try:
        ipoc = _long(raw, "IPOC")
    except PacketError as error:
        raise PacketError(str(error), "ipoc") from None
    if not 0 <= ipoc <= _MAX_IPOC:
        raise PacketError(f"IPOC {ipoc} is out of range", "ipoc")
    return ipoc


def _bool(raw: str, key: str) -> bool:
    text = raw.strip().upper()
    if text in ("1", "TRUE"):
        return True
    if text in ("0", "FALSE"):
        return False
    raise PacketError(f"{key}={raw[:32]!r} is not a boolean (0, 1, TRUE, FALSE)")


def _string(raw: str, key: str) -> str:
    if len(raw) > _MAX_STRING:
        raise PacketError(f"{key} is longer than {_MAX_STRING} characters")
    return raw


_CONVERTERS = {"DOUBLE": _double, "LONG": _long, "BOOL": _bool, "STRING": _string}
_FORMATS = {"DOUBLE": _DOUBLE_FORMAT, "LONG": "%d", "BOOL": "%d", "STRING": "%s"}
_DEFAULTS: dict[str, Value] = {"DOUBLE": 0.0, "LONG": 0, "BOOL": False, "STRING": ""}


def _layout_pattern(root: str, type_value: str, groups: dict[str, list[int]], fields: tuple[Field, ...]) -> re.Pattern[str]:
    """A pattern for a packet in exactly the configured layout; values without markup or entities."""
    ws = r"\s*"
    parts = [ws, f"<{root}", r"\s+", f'(?i:{ROOT_ATTRIBUTE})="{re.escape(type_value)}"', ws, ">"]
    for name, idx in groups.items():
        if fields[idx[0]].attribute is None:
            parts += [ws, f"<{name}>", "([^<&]*)", f"</{name}", ws, ">"]
        else:
            parts += [ws, f"<{name}"]
            for i in idx:
                parts += [r"\s+", f"(?i:{re.escape(str(fields[i].attribute))})", ws, "=", ws, '"([^"<&]*)"']
            parts += [ws, "/>"]
    parts += [ws, "<IPOC>", "([^<&]*)", "</IPOC", ws, ">", ws, f"</{root}", ws, ">", ws]
    return re.compile("".join(parts))


#: The prefix a digit-led attribute name (kroshu's ``GPIO.01``: attribute ``01``) takes for lxml, and loses again.
_DIGIT_PREFIX = "_rsi_"
_TAG_TEXT = re.compile(rb"<([A-Za-z_][\w.-]*)((?:\s+[^\s=<>/\"']+\s*=\s*(?:\"[^\"]*\"|'[^']*'))*)(\s*/?)>")
_ATTRIBUTE = re.compile(rb"(\s+)(\d[\w.-]*)(\s*=\s*(?:\"[^\"]*\"|'[^']*'))")


def _name_digit_attributes(data: bytes) -> bytes:
    """``data`` with every attribute name that starts with a digit -- which RSI writes for ``GPIO.01``, and
    which is no XML name -- prefixed, so lxml reads the packet; only names are touched, never a value."""

    def tag(match: re.Match[bytes]) -> bytes:
        attributes = _ATTRIBUTE.sub(lambda a: a.group(1) + _DIGIT_PREFIX.encode() + a.group(2) + a.group(3), match.group(2))
        return b"<" + match.group(1) + attributes + match.group(3) + b">"

    return _TAG_TEXT.sub(tag, data)


def _attributes(element: etree._Element) -> dict[str, str]:
    """An element's attributes by lower-case name; one name in two spellings is refused."""
    found: dict[str, str] = {}
    for name, value in element.attrib.items():
        key = str(name).removeprefix(_DIGIT_PREFIX).lower()
        if key in found:
            raise PacketError(f"<{element.tag}> gives attribute {name!s} twice, in two spellings", "duplicate")
        found[key] = str(value)
    return found


class PacketCodec:
    """Encoder and decoder of one packet direction (``Rob`` or ``Sen``) of one configuration."""

    def __init__(self, fields: Sequence[Field], root: str, type_value: str, max_bytes: int = MAX_PACKET_BYTES) -> None:
        self.fields = tuple(fields)
        self.root = root
        self.type_value = type_value
        self.max_bytes = max_bytes
        self.keys = tuple(f.key for f in self.fields)
        self.index = {key: i for i, key in enumerate(self.keys)}
        self.defaults: tuple[Value, ...] = tuple(_DEFAULTS[f.type] for f in self.fields)
        self._has_strings = any(f.type == "STRING" for f in self.fields)
        # Group values by element, elements in order of first appearance.
        groups: dict[str, list[int]] = {}
        for i, f in enumerate(self.fields):
            groups.setdefault(f.element, []).append(i)
        self._groups = {
            name: tuple((i, self.fields[i].attribute, _CONVERTERS[self.fields[i].type], self.fields[i].key) for i in idx)
            for name, idx in groups.items()
        }
        order = [i for idx in groups.values() for i in idx]
        self._slot_order: tuple[int, ...] | None = None if order == list(range(len(order))) else tuple(order)
        parts = [f'<{root} Type="{type_value}">']
        for name, idx in groups.items():
            first = self.fields[idx[0]]
            if first.attribute is None:
                parts.append(f"<{name}>{_FORMATS[first.type]}</{name}>")
            else:
                attrs = " ".join(f'{self.fields[i].attribute}="{_FORMATS[self.fields[i].type]}"' for i in idx)
                parts.append(f"<{name} {attrs}/>")
        parts.append(f"<IPOC>%d</IPOC></{root}>")
        self._template = "".join(parts).encode("ascii")
        self._fast = _layout_pattern(root, type_value, groups, self.fields)
        self._fast_fields = tuple((i, _CONVERTERS[self.fields[i].type], self.fields[i].key) for i in order)
        self._digit_names = any(f.attribute is not None and f.attribute[:1].isdigit() for f in self.fields)
        self._parser = etree.XMLParser(
            resolve_entities=False, no_network=True, load_dtd=False, huge_tree=False, remove_comments=True, remove_pis=True
        )

    @classmethod
    def rob(cls, config: RsiConfig, max_bytes: int = MAX_PACKET_BYTES) -> PacketCodec:
        """Controller -> external system."""
        return cls(config.send_fields, "Rob", ROB_TYPE, max_bytes)

    @classmethod
    def sen(cls, config: RsiConfig, max_bytes: int = MAX_PACKET_BYTES) -> PacketCodec:
        """External system -> controller; its ``Type`` is the configured SENTYPE."""
        return cls(config.receive_fields, "Sen", config.sentype, max_bytes)

    # ------------------------------------------------------------------------------ encode
    def encode(self, values: Sequence[Value], ipoc: int) -> bytes:
        """The packet for ``values`` (in field order) and ``ipoc``: one formatting of the template."""
        if self._slot_order is not None:
            values = [values[i] for i in self._slot_order]
        if self._has_strings:
            values = [escape(v).encode("utf-8") if isinstance(v, str) else v for v in values]
        return self._template % (*values, ipoc)

    def encode_map(self, values: Mapping[str, Value], ipoc: int) -> bytes:
        """The packet for ``{key: value}``; keys not given take their type's zero value."""
        unknown = set(values) - set(self.index)
        if unknown:
            raise KeyError(f"not in the <{self.root}> configuration: {', '.join(sorted(unknown))}")
        return self.encode([values.get(k, d) for k, d in zip(self.keys, self.defaults)], ipoc)

    # ------------------------------------------------------------------------------ decode
    def decode_into(self, data: bytes, out: list[Value]) -> int:
        """Parse ``data`` into ``out`` (field order; untouched on error) and return its IPOC."""
        size = len(data)
        if size > self.max_bytes:
            raise PacketError(f"datagram of {size} bytes exceeds the {self.max_bytes}-byte limit", "size")
        if b"<!" in data or b"<?" in data:
            raise PacketError("declarations, DTDs, entities and processing instructions are not allowed in a packet", "markup")
        if data.isascii():
            match = self._fast.fullmatch(data.decode("ascii"))
            if match is not None:
                return self._take(match, out)
        try:
            root = etree.fromstring(_name_digit_attributes(data) if self._digit_names else data, self._parser)
        except etree.XMLSyntaxError as error:
            raise PacketError(f"not well-formed XML: {' '.join(str(error.msg or error).split())}", "xml") from None  # one line
        if root.tag != self.root:
            raise PacketError(f"root element <{root.tag}> where <{self.root}> is expected", "root element")
        attributes = _attributes(root)
        kind = attributes.get(ROOT_ATTRIBUTE.lower())
        if kind is None:
            names = ", ".join(str(k) for k in root.attrib) or "none"
            raise PacketError(f"<{self.root}> has no {ROOT_ATTRIBUTE} attribute (its attributes: {names})", "root attribute")
        if kind != self.type_value:
            raise PacketError(f"<{self.root} {ROOT_ATTRIBUTE}={kind!r}> where {self.type_value!r} is configured", "root type")
        staged: list[tuple[int, Value]] = []
        seen: set[str] = set()
        ipoc = -1
        for child in root:
            tag = child.tag
            if tag in seen:
                raise PacketError(f"<{tag}> appears twice", "duplicate")
            seen.add(tag)
            if tag == "IPOC":
                ipoc = _ipoc(child.text or "")
                continue
            group = self._groups.get(tag)
            if group is None:
                continue  # a value this configuration does not use
            values = _attributes(child)
            for index, attribute, convert, key in group:
                raw = child.text if attribute is None else values.get(attribute.lower())
                if raw is None:
                    raise PacketError(f"{key} is missing", "missing")
                staged.append((index, convert(raw, key)))
        if ipoc < 0:
            raise PacketError("IPOC is missing", "ipoc")
        if len(staged) != len(self.fields):
            missing = [k for k in self.keys if self._element_of(k) not in seen]
            raise PacketError(f"missing values: {', '.join(missing[:6])}", "missing")
        for index, value in staged:
            out[index] = value
        return ipoc

    def _take(self, match: re.Match[str], out: list[Value]) -> int:
        """The values of a packet the layout pattern matched: converted and checked, then stored."""
        texts = match.groups()
        staged = [(index, convert(texts[k], key)) for k, (index, convert, key) in enumerate(self._fast_fields)]
        ipoc = _ipoc(texts[-1])
        for index, value in staged:
            out[index] = value
        return ipoc

    def decode(self, data: bytes) -> tuple[int, dict[str, Value]]:
        """Parse ``data`` into ``(ipoc, {key: value})`` (convenient, not for the hot path)."""
        out: list[Value] = list(self.defaults)
        ipoc = self.decode_into(data, out)
        return ipoc, dict(zip(self.keys, out))

    def _element_of(self, key: str) -> str:
        return self.fields[self.index[key]].element
