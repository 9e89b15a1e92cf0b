"""The RSI Ethernet configuration: which values travel in ``<Rob>`` and ``<Sen>`` packets.

RSI fixes no packet layout; the controller builds and parses packets from an XML file (the
ETHERNET object's configuration, seed 003 Fig. 2).  Both sides of this package -- the external
system and the controller simulator -- read the *same* file, so they cannot disagree on a tag.

The file is outside input, so it is read the hardened way: size limit, no DTD, no entity, no
network, and every mistake reported with the file, the line and the field.  Each ``ELEMENT``
expands into :class:`Field` s, the single values of a packet:

* ``DEF_RIst`` (INDEX ``INTERNAL``) -> ``RIst.X`` ... ``RIst.C``: the keywords KUKA defines;
* ``Digout.o1`` -> attribute ``o1`` of a ``<Digout>`` element (the dotted form RSI uses);
* ``D1`` -> the text of a ``<D1>`` element (the form of Fig. 2).
"""
from __future__ import annotations

import functools
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from lxml import etree

ValueType = Literal["BOOL", "LONG", "DOUBLE", "STRING"]
VALUE_TYPES: tuple[str, ...] = ("BOOL", "LONG", "DOUBLE", "STRING")

#: Largest configuration file accepted; a real one is a few kB.
MAX_CONFIG_BYTES = 64 * 1024
#: RSI offers at most 64 channels on the ETHERNET object.
MAX_INDEX = 64
DEFAULT_PORT = 49152
#: The file installed with the package (``config/kuka_rsi_ethernet.xml``).
DEFAULT_CONFIG_NAME = "kuka_rsi_ethernet.xml"

_CARTESIAN = ("X", "Y", "Z", "A", "B", "C")
_AXES = ("A1", "A2", "A3", "A4", "A5", "A6")
_EXTERNAL = ("E1", "E2", "E3", "E4", "E5", "E6")

#: The INTERNAL keywords of the SEND section: element name, attributes, required TYPE.
_INTERNAL_SEND: dict[str, tuple[str, tuple[str, ...], ValueType]] = {
    "DEF_RIst": ("RIst", _CARTESIAN, "DOUBLE"),
    "DEF_RSol": ("RSol", _CARTESIAN, "DOUBLE"),
    "DEF_AIPos": ("AIPos", _AXES, "DOUBLE"),
    "DEF_ASPos": ("ASPos", _AXES, "DOUBLE"),
    "DEF_EIPos": ("EIPos", _EXTERNAL, "DOUBLE"),
    "DEF_ESPos": ("ESPos", _EXTERNAL, "DOUBLE"),
    "DEF_MACur": ("MACur", _AXES, "DOUBLE"),
    "DEF_MECur": ("MECur", _EXTERNAL, "DOUBLE"),
    "DEF_Delay": ("Delay", ("D",), "LONG"),
}
#: Function generators of the technology parameters (``$TECHPAR_C`` / ``$TECHPAR``): RSI names 1..6.
TECH_GENERATORS = 6
#: ``DEF_Tech.C<n>`` (advance run) and ``DEF_Tech.T<n>`` (main run): the ten parameters of generator n,
#: attributes ``C<n>1`` .. ``C<n>10`` of one shared ``<Tech>`` element, as KUKA's RSI puts them on the wire.
_TECH: dict[str, tuple[str, tuple[str, ...], ValueType]] = {
    f"DEF_Tech.{run}{n}": ("Tech", tuple(f"{run}{n}{m}" for m in range(1, 11)), "DOUBLE")
    for run in ("C", "T")
    for n in range(1, TECH_GENERATORS + 1)
}
_INTERNAL_SEND.update(_TECH)
#: The INTERNAL keywords of the RECEIVE section: a message shown on the teach pendant, technology parameters.
_INTERNAL_RECEIVE: dict[str, tuple[str, tuple[str, ...], ValueType]] = {
    "DEF_EStr": ("EStr", (), "STRING"),
    **_TECH,
}

_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
# The attribute of a dotted TAG may start with a digit: kroshu's GPIO configurations name ``GPIO.01``,
# which RSI writes as attribute ``01`` of ``<GPIO>`` (not an XML name; KUKA's own parsers scan for it).
_TAG = re.compile(rf"^{_NAME}(\.[A-Za-z0-9_]+)?$")


class ConfigError(ValueError):
    """The configuration file is unusable; the message names the file, line and field."""


@dataclass(frozen=True)
class Field:
    """One value of a packet: ``<element attribute="...">`` or, without attribute, ``<element>text</element>``."""

    key: str  # "RIst.X", "Digout.o1", "D1"
    element: str
    attribute: str | None
    type: ValueType
    holdon: bool = False  # RECEIVE only: keep the last value when a packet is late


@dataclass(frozen=True)
class Element:
    """One ``<ELEMENT>`` line of the file, as written (kept for error messages and docs)."""

    tag: str
    type: ValueType
    index: int | None  # None for INTERNAL
    holdon: bool
    line: int


@dataclass(frozen=True)
class RsiConfig:
    """A parsed RSI Ethernet configuration."""

    ip: str
    port: int
    sentype: str
    onlysend: bool
    send: tuple[Element, ...]
    receive: tuple[Element, ...]
    source: str = "<string>"

    @property
    def send_fields(self) -> tuple[Field, ...]:
        """The values of a ``<Rob>`` packet, in packet order (IPOC not included)."""
        return _expand(self.send, _INTERNAL_SEND)

    @property
    def receive_fields(self) -> tuple[Field, ...]:
        """The values of a ``<Sen>`` packet, in packet order (IPOC not included)."""
        return _expand(self.receive, _INTERNAL_RECEIVE)

    def has_send(self, *keys: str) -> bool:
        known = {f.key for f in self.send_fields}
        return all(k in known for k in keys)

    def has_receive(self, *keys: str) -> bool:
        known = {f.key for f in self.receive_fields}
        return all(k in known for k in keys)


def _expand(elements: tuple[Element, ...], internal: dict[str, tuple[str, tuple[str, ...], ValueType]]) -> tuple[Field, ...]:
    fields: list[Field] = []
    for el in elements:
        if el.tag in internal:
            name, attrs, vtype = internal[el.tag]
            if attrs:
                fields.extend(Field(f"{name}.{a}", name, a, vtype, el.holdon) for a in attrs)
            else:
                fields.append(Field(name, name, None, vtype, el.holdon))
        elif "." in el.tag:
            name, attr = el.tag.split(".", 1)
            fields.append(Field(el.tag, name, attr, el.type, el.holdon))
        else:
            fields.append(Field(el.tag, el.tag, None, el.type, el.holdon))
    return tuple(fields)


# ------------------------------------------------------------------------------------ parsing
def _parser() -> etree.XMLParser:
    return etree.XMLParser(
        resolve_entities=False, no_network=True, load_dtd=False, dtd_validation=False, huge_tree=False, remove_comments=True
    )


def load_config(path: str | Path) -> RsiConfig:
    """Read and check an RSI Ethernet configuration file."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as error:
        raise ConfigError(f"{path}: cannot read RSI configuration: {error.strerror or error}") from None
    if size > MAX_CONFIG_BYTES:
        raise ConfigError(f"{path}: RSI configuration is {size} bytes, more than the {MAX_CONFIG_BYTES} allowed")
    return parse_config(path.read_bytes(), source=str(path))


def parse_config(data: bytes | str, source: str = "<string>") -> RsiConfig:
    """Parse the text of an RSI Ethernet configuration; ``source`` names it in errors."""
    raw = data.encode("utf-8") if isinstance(data, str) else data
    if len(raw) > MAX_CONFIG_BYTES:
        raise ConfigError(f"{source}: RSI configuration is {len(raw)} bytes, more than the {MAX_CONFIG_BYTES} allowed")
    for marker in (b"<!DOCTYPE", b"<!ENTITY"):
        at = raw.find(marker)
        if at >= 0:
            line = raw.count(b"\n", 0, at) + 1
            raise ConfigError(f"{source}:{line}: DOCTYPE and ENTITY declarations are not allowed in an RSI configuration")
    try:
        root = etree.fromstring(raw, _parser())
    except etree.XMLSyntaxError as error:
        # lxml's message may run over lines (a NUL byte: "... out of allowed range\n, line 2, column 101"): one line
        raise ConfigError(f"{source}:{error.lineno}: not well-formed XML: {' '.join(str(error.msg).split())}") from None
    return _read_root(root, source)


def _where(source: str, node: etree._Element) -> str:
    return f"{source}:{node.sourceline}"


def _child(parent: etree._Element, name: str, source: str) -> etree._Element:
    found = parent.findall(name)
    if len(found) != 1:
        what = "missing" if not found else f"given {len(found)} times"
        raise ConfigError(f"{_where(source, parent)}: <{parent.tag}> needs exactly one <{name}> ({what})")
    return found[0]


def _text(parent: etree._Element, name: str, source: str) -> tuple[str, etree._Element]:
    node = _child(parent, name, source)
    text = (node.text or "").strip()
    if not text:
        raise ConfigError(f"{_where(source, node)}: <{name}> is empty")
    return text, node


def _read_root(root: etree._Element, source: str) -> RsiConfig:
    if root.tag != "ROOT":
        raise ConfigError(f"{_where(source, root)}: the root element must be <ROOT>, not <{root.tag}>")
    config = _child(root, "CONFIG", source)
    ip, _ = _text(config, "IP_NUMBER", source)
    port_text, port_node = _text(config, "PORT", source)
    if not port_text.isdigit() or not 0 < int(port_text) < 65536:
        raise ConfigError(f"{_where(source, port_node)}: <PORT> must be a UDP port 1..65535, got {port_text!r}")
    sentype, sentype_node = _text(config, "SENTYPE", source)
    if not re.match(rf"^{_NAME}$", sentype) or len(sentype) > 64:
        raise ConfigError(f"{_where(source, sentype_node)}: <SENTYPE> must be a plain name (letters, digits, '_'), got {sentype!r}")
    onlysend_text, onlysend_node = _text(config, "ONLYSEND", source)
    if onlysend_text.upper() not in ("TRUE", "FALSE"):
        raise ConfigError(f"{_where(source, onlysend_node)}: <ONLYSEND> must be TRUE or FALSE, got {onlysend_text!r}")
    send = _read_section(root, "SEND", source, _INTERNAL_SEND)
    receive = _read_section(root, "RECEIVE", source, _INTERNAL_RECEIVE) if root.find("RECEIVE") is not None else ()
    result = RsiConfig(ip, int(port_text), sentype, onlysend_text.upper() == "TRUE", send, receive, source)
    _check_fields(result.send_fields, "SEND", source)
    _check_fields(result.receive_fields, "RECEIVE", source)
    return result


def _read_section(
    root: etree._Element, name: str, source: str, internal: dict[str, tuple[str, tuple[str, ...], ValueType]]
) -> tuple[Element, ...]:
    section = _child(root, name, source)
    elements = _child(section, "ELEMENTS", source)
    result: list[Element] = []
    tags: dict[str, int] = {}
    indices: dict[int, int] = {}
    for node in elements:
        if node.tag != "ELEMENT":
            raise ConfigError(f"{_where(source, node)}: unexpected <{node.tag}> in <{name}><ELEMENTS>")
        element = _read_element(node, name, source, internal)
        where = _where(source, node)
        if element.tag in tags:
            raise ConfigError(f"{where}: TAG {element.tag!r} already given on line {tags[element.tag]}")
        tags[element.tag] = element.line
        if element.index is not None:
            if element.index in indices:
                raise ConfigError(f"{where}: INDEX {element.index} already used on line {indices[element.index]}")
            indices[element.index] = element.line
        result.append(element)
    return tuple(result)


def _read_element(
    node: etree._Element, section: str, source: str, internal: dict[str, tuple[str, tuple[str, ...], ValueType]]
) -> Element:
    where = _where(source, node)
    tag = node.get("TAG")
    if not tag or not _TAG.match(tag):
        raise ConfigError(f"{where}: TAG must be a name or 'element.attribute', got {tag!r}")
    vtype = node.get("TYPE", "")
    if vtype not in VALUE_TYPES:
        raise ConfigError(f"{where}: TYPE of {tag} must be one of {', '.join(VALUE_TYPES)}, got {vtype!r}")
    # Fig. 2 of the seed writes INDEX; KUKA's own examples write INDX.  Both mean the same.
    index_text = node.get("INDEX", node.get("INDX"))
    if index_text is None:
        raise ConfigError(f"{where}: {tag} needs an INDEX")
    holdon_text = node.get("HOLDON", "0")
    if holdon_text not in ("0", "1"):
        raise ConfigError(f"{where}: HOLDON of {tag} must be 0 or 1, got {holdon_text!r}")
    if holdon_text == "1" and section == "SEND":
        raise ConfigError(f"{where}: HOLDON applies to RECEIVE elements only ({tag} is in SEND)")
    if tag.startswith("DEF_"):
        if tag not in internal:
            known = ", ".join(sorted(k for k in internal if k not in _TECH))
            if any(k in _TECH for k in internal):
                known += f", DEF_Tech.C1..C{TECH_GENERATORS}, DEF_Tech.T1..T{TECH_GENERATORS}"
            raise ConfigError(f"{where}: {tag} is not a {section} keyword (known: {known})")
        if index_text != "INTERNAL":
            raise ConfigError(f"{where}: {tag} needs INDEX=\"INTERNAL\", got {index_text!r}")
        required = internal[tag][2]
        if vtype != required:
            raise ConfigError(f"{where}: {tag} has TYPE {required}, not {vtype}")
        return Element(tag, vtype, None, holdon_text == "1", node.sourceline or 0)  # type: ignore[arg-type]
    if tag == "IPOC" or tag.startswith("IPOC."):
        raise ConfigError(f"{where}: IPOC is added to every packet by RSI itself; do not configure it")
    if not index_text.isdigit() or not 1 <= int(index_text) <= MAX_INDEX:
        raise ConfigError(f"{where}: INDEX of {tag} must be INTERNAL or 1..{MAX_INDEX}, got {index_text!r}")
    return Element(tag, vtype, int(index_text), holdon_text == "1", node.sourceline or 0)  # type: ignore[arg-type]


def _check_fields(fields: tuple[Field, ...], section: str, source: str) -> None:
    """An element carries either attributes or text, never both; keys are unique."""
    text_elements = {f.element for f in fields if f.attribute is None}
    attr_elements = {f.element for f in fields if f.attribute is not None}
    clash = text_elements & attr_elements
    if clash:
        name = sorted(clash)[0]
        raise ConfigError(f"{source}: <{section}> uses <{name}> both as a value and with attributes ({name}.x)")
    if "IPOC" in text_elements | attr_elements:
        raise ConfigError(f"{source}: <{section}> must not configure IPOC")
    keys = [f.key for f in fields]
    duplicates = sorted({k for k in keys if keys.count(k) > 1})
    if duplicates:
        raise ConfigError(f"{source}: <{section}> defines {duplicates[0]} twice (a keyword and an element overlap)")


def default_config_path() -> Path:
    """The RSI configuration shipped with the package: source tree first, then the installed share/."""
    here = Path(__file__).resolve()
    candidates = [here.parents[2] / "config" / DEFAULT_CONFIG_NAME]
    candidates.append(Path(sys.prefix) / "share" / "dual_arm_executive" / "config" / DEFAULT_CONFIG_NAME)
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise ConfigError(f"default RSI configuration {DEFAULT_CONFIG_NAME} not found (looked in {', '.join(map(str, candidates))})")


@functools.lru_cache(maxsize=1)
def default_config() -> RsiConfig:
    """The package's configuration, read once (a parsed configuration is immutable)."""
    return load_config(default_config_path())


@dataclass(frozen=True)
class RsiRoles:
    """What the configured tags *mean*: which carry corrections, handshakes, tool outputs.

    The defaults name the tags of ``config/kuka_rsi_ethernet.xml``; a controller configured with
    other names passes its own.  A role whose tag is absent from the configuration is simply not
    available (no handshake, no Cartesian correction, ...), and the parts that need it say so.
    """

    axis_correction: tuple[str, ...] = ("AK.A1", "AK.A2", "AK.A3", "AK.A4", "AK.A5", "AK.A6")
    cart_correction: tuple[str, ...] = ("RKorr.X", "RKorr.Y", "RKorr.Z", "RKorr.A", "RKorr.B", "RKorr.C")
    stop: str = "Stop"
    # Handshake flags sent to the KRL program (ITRA's allowRobotStart / allowRobMove /
    # allowRobotFinish / requRealTimeEnd) and the outputs by which it acknowledges them.
    allow_start: str = "B1"
    allow_move: str = "B2"
    allow_finish: str = "B3"
    request_end: str = "B4"
    task_active: str = "Digout.o1"
    correction_active: str = "Digout.o2"
    move_required: str = "Digout.o3"
    realtime_ended: str = "Digout.o4"
    #: Tool outputs in the order gripper (closed = 1), air, tool spindle; the robot echoes them in <Rob>.
    tool_outputs: tuple[str, ...] = ("Tool.o1", "Tool.o2", "Tool.o3")

    def handshake(self, config: RsiConfig) -> bool:
        """True when the configuration carries all four flags and all four acknowledgements."""
        return config.has_receive(self.allow_start, self.allow_move, self.allow_finish, self.request_end) and config.has_send(
            self.task_active, self.correction_active, self.move_required, self.realtime_ended
        )

    def axis(self, config: RsiConfig) -> bool:
        return config.has_receive(*self.axis_correction)

    def cartesian(self, config: RsiConfig) -> bool:
        return config.has_receive(*self.cart_correction)

    def tools(self, config: RsiConfig) -> tuple[str, ...]:
        """The tool outputs present in both directions (commanded in <Sen>, echoed in <Rob>)."""
        return tuple(t for t in self.tool_outputs if config.has_receive(t) and config.has_send(t))


#: The feedback values the external system reads from every ``<Rob>`` packet.
FEEDBACK_KEYS: tuple[str, ...] = tuple(
    f"{element}.{axis}"
    for element, axes in (("RIst", _CARTESIAN), ("RSol", _CARTESIAN), ("AIPos", _AXES), ("ASPos", _AXES))
    for axis in axes
)
