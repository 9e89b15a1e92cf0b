"""Plain CDR (XCDR1, little endian) of the IDL types, compiled once per type into Python code.

Why: cyclonedds-python encodes and decodes a sample by walking a tree of "machines", one Python
call and one ``struct`` call per field, each with its alignment computed at run time; that was
most of what a DDS message cost its writer and its reader (issue 22: a quarter of a machine's main
thread under cProfile).  Here each wire type gets one generated function per direction: runs of
fixed-size fields whose offsets are known when the type is compiled are one ``struct.Struct``
call with their padding in its format, alignment is computed only after a string or a sequence,
and nested structures are inlined.

The bytes are cyclonedds-python's, byte for byte (the encapsulation header ``00 01 00 00``, 8-byte
alignment counted from after the header, strings with their NUL, the sample padded to 4 bytes):
``test/test_dds_cdr.py`` checks both directions against cyclonedds for every interface type of the
project.  A type with something this compiler does not know (unions, enums, optionals, XCDR2's
delimited or mutable types) keeps cyclonedds's own serializer; a received sample in another
encoding (big endian, XCDR2) is decoded by cyclonedds.
"""
from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

HEADER = b"\x00\x01\x00\x00"  # CDR_LE, no options: what cyclonedds writes on a little-endian host
_MAX_ALIGN = 8  # XCDR1
_ZEROS = tuple(bytes(n) for n in range(8))
_U32 = struct.Struct("<I")


class CdrError(ValueError):
    """A value that plain CDR of its type cannot carry, or bytes that are not such a sample."""


class Unsupported(Exception):
    """A type this compiler leaves to cyclonedds."""


def _machine_kind(machine: Any) -> str:
    return type(machine).__name__


class _Alignment:
    """What is known at compile time of the offset from the start of the data: ``offset % modulus``."""

    def __init__(self, residue: int = 0, modulus: int = _MAX_ALIGN) -> None:
        self.residue, self.modulus = residue, modulus

    def static_pad(self, alignment: int) -> int | None:
        """The padding before a field aligned to ``alignment``, or None when only the run time knows it."""
        alignment = min(alignment, _MAX_ALIGN)
        if alignment <= self.modulus:
            return (-self.residue) % alignment
        return None

    def advance(self, size: int) -> None:
        self.residue = (self.residue + size) % self.modulus

    def aligned_at_run_time(self, alignment: int) -> None:
        alignment = min(alignment, _MAX_ALIGN)
        if alignment > self.modulus:
            self.residue, self.modulus = 0, alignment

    def unknown(self) -> None:
        self.residue, self.modulus = 0, 1


class _Source:
    """Lines of one generated function, with a pending run of fixed-size fields (one Struct)."""

    def __init__(self, namespace: dict[str, Any], names: Callable[[str], str]) -> None:
        self.namespace = namespace
        self.fresh = names
        self.lines: list[str] = []
        self.fmt = "<"
        self.items: list[str] = []  # encode: value expressions; decode: target names
        self.size = 0
        self.align = _Alignment()

    def constant(self, value: Any, stem: str) -> str:
        name = self.fresh(stem)
        self.namespace[name] = value
        return name

    def add_fixed(self, code: str, alignment: int, size: int, item: str) -> None:
        pad = self.align.static_pad(alignment)
        if pad is None:
            self.flush()
            self.dynamic_align(alignment)
            pad = 0
        self.fmt += "x" * pad + code
        self.items.append(item)
        self.size += pad + size
        self.align.advance(pad + size)


class _Encoder(_Source):
    """``b`` is the bytearray being written (the header first), ``v`` the sample."""

    def flush(self) -> None:
        if self.items:
            packer = self.constant(struct.Struct(self.fmt), "S")
            self.lines.append(f"b += {packer}.pack({', '.join(self.items)})")
        self.fmt, self.items, self.size = "<", [], 0

    def dynamic_align(self, alignment: int) -> None:
        alignment = min(alignment, _MAX_ALIGN)
        if alignment > 1 and self.align.static_pad(alignment) is None:
            self.lines.append(f"b += Z[(4 - len(b)) & {alignment - 1}]")
        elif alignment > 1:
            pad = self.align.static_pad(alignment)
            if pad:
                self.lines.append(f"b += Z[{pad}]")
                self.align.advance(pad)
        self.align.aligned_at_run_time(alignment)

    def field(self, machine: Any, value: str, where: str) -> None:
        kind = _machine_kind(machine)
        if kind == "PrimitiveMachine":
            self.add_fixed(machine.code, machine.alignment, machine.size, value)
        elif kind == "InstanceMachine":
            nested = _v1(machine.type)
            local = self.fresh("v")
            self.lines.append(f"{local} = {value}")
            for name, member in nested.members_machines.items():
                self.field(member, f"{local}.{name}", f"{where}.{name}")
        elif kind == "ByteArrayMachine":
            local = self.fresh("v")
            self.lines.append(f"{local} = bytes({value})")
            self.lines.append(f"if len({local}) != {machine.size}: raise CdrError({where + ': an array of ' + str(machine.size) + ' octets'!r})")
            self.add_fixed(f"{machine.size}s", 1, machine.size, local)
        elif kind == "PlainCdrV2ArrayOfPrimitiveMachine":
            local = self.fresh("v")
            self.lines.append(f"{local} = {value}")
            self.lines.append(f"if len({local}) != {machine.length}: raise CdrError({where + ': an array of ' + str(machine.length)!r})")
            self.add_fixed(machine.code, machine.alignment, machine.size, f"*{local}")
        else:
            self.flush()
            self.variable(machine, value, where)

    def variable(self, machine: Any, value: str, where: str) -> None:
        """A field whose size only the run time knows; afterwards the offset is unknown."""
        kind = _machine_kind(machine)
        local = self.fresh("v")
        self.lines.append(f"{local} = {value}")
        if kind == "StringMachine":
            if machine.bound:
                self.lines.append(f"if len({local}) > {machine.bound}: raise CdrError({where + ': longer than ' + str(machine.bound)!r})")
            encoded = self.fresh("s")
            self.dynamic_align(4)
            self.lines.append(f"{encoded} = {local}.encode()")
            self.lines.append(f"b += U32.pack(len({encoded}) + 1); b += {encoded}; b += Z[1]")
        elif kind == "BytesMachine":
            if machine.bound:
                self.lines.append(f"if len({local}) > {machine.bound}: raise CdrError({where + ': longer than ' + str(machine.bound)!r})")
            self.dynamic_align(4)
            self.lines.append(f"b += U32.pack(len({local})); b += {local}")
        elif kind == "PlainCdrV2SequenceOfPrimitiveMachine":
            if machine.max_length is not None:
                self.lines.append(f"if len({local}) > {machine.max_length}: raise CdrError({where + ': more than ' + str(machine.max_length)!r})")
            self.dynamic_align(4)
            self.lines.append(f"b += U32.pack(len({local}))")
            self.lines.append(f"if {local}:")
            alignment = min(machine.alignment, _MAX_ALIGN)
            if alignment > 4:
                self.lines.append(f"    b += Z[(4 - len(b)) & {alignment - 1}]")
            self.lines.append(f"    b += pack('<%d{machine.code}' % len({local}), *{local})")
        elif kind in ("SequenceMachine", "ArrayMachine"):
            element = self.constant(_element_encoder(_plain(machine).submachine, f"{where}[]"), "e")
            if kind == "SequenceMachine":
                if machine.maxlen is not None:
                    self.lines.append(f"if len({local}) > {machine.maxlen}: raise CdrError({where + ': more than ' + str(machine.maxlen)!r})")
                self.dynamic_align(4)
                self.lines.append(f"b += U32.pack(len({local}))")
            else:
                self.lines.append(f"if len({local}) != {machine.size}: raise CdrError({where + ': an array of ' + str(machine.size)!r})")
            item = self.fresh("i")
            self.lines.append(f"for {item} in {local}: {element}(b, {item})")
        else:
            raise Unsupported(f"{kind} ({where})")
        self.align.unknown()


class _Decoder(_Source):
    """``d`` holds the sample (the header first), ``p`` is the offset being read."""

    def __init__(self, namespace: dict[str, Any], names: Callable[[str], str]) -> None:
        super().__init__(namespace, names)
        self.post: list[str] = []  # structures built once their fields are read

    def flush(self) -> None:
        if self.items:
            reader = self.constant(struct.Struct(self.fmt), "S")
            targets = ", ".join(self.items) + ("," if len(self.items) == 1 else "")
            self.lines.append(f"{targets} = {reader}.unpack_from(d, p); p += {self.size}")
        self.fmt, self.items, self.size = "<", [], 0

    def dynamic_align(self, alignment: int) -> None:
        alignment = min(alignment, _MAX_ALIGN)
        pad = self.align.static_pad(alignment)
        if alignment > 1 and pad is None:
            self.lines.append(f"p += (4 - p) & {alignment - 1}")
        elif pad:
            self.lines.append(f"p += {pad}")
            self.align.advance(pad)
        self.align.aligned_at_run_time(alignment)

    def field(self, machine: Any, where: str) -> str:
        """Code reading the field; the name of the local holding its value once ``post`` has run."""
        kind = _machine_kind(machine)
        target = self.fresh("t")
        if kind == "PrimitiveMachine":
            self.add_fixed(machine.code, machine.alignment, machine.size, target)
        elif kind == "InstanceMachine":
            nested = _v1(machine.type)
            members = [self.field(member, f"{where}.{name}") for name, member in nested.members_machines.items()]
            cls = self.constant(nested.type, "C")
            self.post.append(f"{target} = {cls}({', '.join(members)})")
        elif kind == "ByteArrayMachine":
            self.add_fixed(f"{machine.size}s", 1, machine.size, target)
        elif kind == "PlainCdrV2ArrayOfPrimitiveMachine":
            raw = self.fresh("t")
            self.add_fixed(f"{machine.size}s", machine.alignment, machine.size, raw)
            self.post.append(f"{target} = list(unpack('<{machine.code}', {raw}))")
        else:
            self.flush()
            self.variable(machine, target, where)
        return target

    def variable(self, machine: Any, target: str, where: str) -> None:
        kind = _machine_kind(machine)
        if kind == "StringMachine":
            self.dynamic_align(4)
            self.lines.append(f"n = U32.unpack_from(d, p)[0]; e = p + 3 + n")
            self.lines.append(f"if n == 0 or e >= len(d): raise CdrError({where + ': a string past the end of the sample'!r})")
            self.lines.append(f"{target} = d[p + 4:e].decode(); p = e + 1")
        elif kind == "BytesMachine":
            self.dynamic_align(4)
            self.lines.append(f"n = U32.unpack_from(d, p)[0]; e = p + 4 + n")
            self.lines.append(f"if e > len(d): raise CdrError({where + ': octets past the end of the sample'!r})")
            self.lines.append(f"{target} = d[p + 4:e]; p = e")
        elif kind == "PlainCdrV2SequenceOfPrimitiveMachine":
            self.dynamic_align(4)
            self.lines.append("n = U32.unpack_from(d, p)[0]; p += 4")
            self.lines.append(f"if n > len(d): raise CdrError({where + ': more elements than the sample has bytes'!r})")
            alignment = min(machine.alignment, _MAX_ALIGN)
            self.lines.append("if n:")
            if alignment > 4:
                self.lines.append(f"    p += (4 - p) & {alignment - 1}")
            self.lines.append(f"    {target} = list(unpack_from('<%d{machine.code}' % n, d, p)); p += n * {machine.size}")
            self.lines.append(f"else: {target} = []")
        elif kind in ("SequenceMachine", "ArrayMachine"):
            element = self.constant(_element_decoder(_plain(machine).submachine, f"{where}[]"), "e")
            if kind == "SequenceMachine":
                self.dynamic_align(4)
                self.lines.append("n = U32.unpack_from(d, p)[0]; p += 4")
                self.lines.append(f"if n > len(d): raise CdrError({where + ': more elements than the sample has bytes'!r})")
            else:
                self.lines.append(f"n = {machine.size}")
            self.lines.append(f"{target} = []")
            self.lines.append(f"for _ in range(n): x, p = {element}(d, p); {target}.append(x)")
        else:
            raise Unsupported(f"{kind} ({where})")
        self.align.unknown()


def _plain(machine: Any) -> Any:
    """``machine``, a sequence or array of XCDR1 (no delimiting header, which XCDR2 has)."""
    if getattr(machine, "add_size_header", False):
        raise Unsupported("a delimited sequence or array (XCDR2)")
    return machine


def _v1(cls: Any) -> Any:
    idl = cls.__idl__
    if idl.v1_machine is None:
        idl.populate()
    machine = idl.v1_machine
    if _machine_kind(machine) != "StructMachine" or getattr(machine, "keylist", None):
        raise Unsupported(f"{_machine_kind(machine)} of {cls.__name__} (only final structures without keys)")
    return machine


def _namespace() -> dict[str, Any]:
    return {"Z": _ZEROS, "U32": _U32, "CdrError": CdrError, "pack": struct.pack, "unpack": struct.unpack,
            "unpack_from": struct.unpack_from}


def _counter() -> Callable[[str], str]:
    counts: dict[str, int] = {}

    def fresh(stem: str) -> str:
        counts[stem] = counts.get(stem, 0) + 1
        return f"{stem}{counts[stem]}"

    return fresh


def _function(name: str, args: str, body: list[str], namespace: dict[str, Any]) -> Callable[..., Any]:
    source = f"def {name}({args}):\n" + "".join(f"    {line}\n" for line in body)
    exec(compile(source, f"<cdr {name}>", "exec"), namespace)  # noqa: S102 - our own generated code, from the IDL types
    function = namespace[name]
    function.source = source  # type: ignore[attr-defined]
    return function  # type: ignore[no-any-return]


def _element_encoder(machine: Any, where: str) -> Callable[[bytearray, Any], None]:
    encoder = _Encoder(_namespace(), _counter())
    encoder.align.unknown()
    if _machine_kind(machine) == "InstanceMachine":
        for name, member in _v1(machine.type).members_machines.items():
            encoder.field(member, f"x.{name}", f"{where}.{name}")
    else:
        encoder.field(machine, "x", where)
    encoder.flush()
    return _function("encode_element", "b, x", encoder.lines or ["pass"], encoder.namespace)


def _element_decoder(machine: Any, where: str) -> Callable[[bytes, int], tuple[Any, int]]:
    decoder = _Decoder(_namespace(), _counter())
    decoder.align.unknown()
    value = decoder.field(machine, where)
    decoder.flush()
    return _function("decode_element", "d, p", [*decoder.lines, *decoder.post, f"return {value}, p"], decoder.namespace)


class CdrCodec:
    """The compiled encoder and decoder of one wire type (an IdlStruct class of the registry)."""

    def __init__(self, wire_type: type) -> None:
        self.wire_type = wire_type
        machine = _v1(wire_type)
        encoder = _Encoder(_namespace(), _counter())
        for name, member in machine.members_machines.items():
            encoder.field(member, f"v.{name}", name)
        encoder.flush()
        body = ["b = bytearray(HEADER)", *encoder.lines, "b += Z[-len(b) & 3]", "return bytes(b)"]
        encoder.namespace["HEADER"] = HEADER
        self.encode: Callable[[Any], bytes] = _function("encode", "v", body, encoder.namespace)
        decoder = _Decoder(_namespace(), _counter())
        decoder.align = _Alignment()
        values = [decoder.field(member, name) for name, member in machine.members_machines.items()]
        decoder.flush()
        cls = decoder.constant(wire_type, "C")
        body = ["p = 4", *decoder.lines, *decoder.post, f"return {cls}({', '.join(values)})"]
        self._decode: Callable[[bytes], Any] = _function("decode", "d", body, decoder.namespace)

    def decode(self, data: bytes) -> Any:
        """The sample of ``data`` (CDR with its encapsulation header); another encoding than
        little-endian plain CDR goes to cyclonedds."""
        if data[:2] != b"\x00\x01":
            return self.wire_type.deserialize(data)  # type: ignore[attr-defined]
        return self._decode(data)


class FallbackCodec:
    """cyclonedds's own serializer, for a type :class:`CdrCodec` does not compile."""

    def __init__(self, wire_type: type) -> None:
        self.wire_type = wire_type

    def encode(self, sample: Any) -> bytes:
        data: bytes = sample.serialize(use_version_2=False)
        return data + _ZEROS[-len(data) & 3]

    def decode(self, data: bytes) -> Any:
        return self.wire_type.deserialize(data)  # type: ignore[attr-defined]


_CODECS: dict[type, CdrCodec | FallbackCodec] = {}


def codec(wire_type: type) -> CdrCodec | FallbackCodec:
    """The codec of ``wire_type``, compiled on first use (any thread: a race compiles it twice)."""
    found = _CODECS.get(wire_type)
    if found is None:
        try:
            found = CdrCodec(wire_type)
        except Unsupported:
            found = FallbackCodec(wire_type)
        _CODECS[wire_type] = found
    return found
