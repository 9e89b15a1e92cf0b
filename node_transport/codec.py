"""Dataclass <-> JSON coding with validation: the contract of every JSON message on the wire.

Structured messages are JSON inside ``std_msgs/String`` or, for the typed topics, put back into
their JSON shape by :mod:`node_transport.typed`.  Whatever arrives is input from
another process, so decoding checks everything against the dataclass's type hints -- required
fields, types, literals, enum values, nested messages, tagged unions, a size limit -- and a
failure raises :class:`WireError` naming the message type, the field path and the source (a
topic or peer).  A garbled message is rejected as a whole and changes nothing.

Supported field types: ``bool``, ``int``, ``float``, ``str``, ``None``, ``Literal[...]``,
``Enum`` (by value), ``X | None``, ``list[T]``, ``tuple[T, ...]``, ``dict[str, T]``, ``Any`` (any
JSON value), nested dataclasses, and unions of dataclasses that each declare a ``KIND`` class
variable (encoded with a ``"kind"`` key).  A field may carry ``metadata={"json": "from"}`` to
use a JSON key that is a Python keyword.
"""
from __future__ import annotations

import dataclasses
import enum
import json
import math
import numbers
import types
import typing
from collections.abc import Callable
from functools import lru_cache
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

T = TypeVar("T")

MAX_MESSAGE_BYTES = 4 * 1024 * 1024
_JSON_SCALARS = (str, int, float, bool, type(None))


class WireError(ValueError):
    """A message that does not match its contract; says which message, field and source."""

    def __init__(self, message: str, *, source: str = "", type_name: str = "", path: str = "") -> None:
        self.source = source
        self.type_name = type_name
        self.path = path
        self.reason = message
        where = " ".join(p for p in (f"from {source}" if source else "", type_name, f"field {path!r}" if path else "") if p)
        super().__init__(f"{where}: {message}" if where else message)


@dataclasses.dataclass(frozen=True)
class FieldPlan:
    """How one field of a message dataclass travels (encode, decode and json_schema.py follow the same plan)."""

    name: str
    key: str
    hint: Any
    required: bool
    omit_none: bool  # default is None: a None value is left out of the JSON


@lru_cache(maxsize=None)
def field_plan(cls: type) -> tuple[FieldPlan, ...]:
    """The plan of each init field of ``cls``, in declaration order (made once per class)."""
    hints = typing.get_type_hints(cls)
    plans = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        plans.append(FieldPlan(f.name, f.metadata.get("json", f.name), hints[f.name], required, f.default is None))
    return tuple(plans)


def is_tagged_union(hint: Any) -> bool:
    """Whether ``hint`` is a union of dataclasses told apart by their ``KIND`` (its value is the JSON tag)."""
    args = get_args(hint)
    members = [a for a in args if a is not type(None)]
    return (
        len(members) > 1
        and all(dataclasses.is_dataclass(a) and isinstance(getattr(a, "KIND", None), str) for a in members)
    )


# ----------------------------------------------------------------------------- encoding
# Messages cross the wire several times per primitive, so each dataclass gets an encoder built
# once from its fields; the per-message work is then attribute reads and dict stores.
_ENCODERS: dict[type, Callable[[Any], dict[str, Any]]] = {}


def _dataclass_encoder(cls: type) -> Callable[[Any], dict[str, Any]]:
    fields = tuple((p.name, p.key, p.omit_none) for p in field_plan(cls))
    kind = getattr(cls, "KIND", None)
    tag = {"kind": kind} if isinstance(kind, str) else {}

    def encode_dataclass(obj: Any) -> dict[str, Any]:
        out = dict(tag)
        for name, key, omit_none in fields:
            value = getattr(obj, name)
            if value is None:
                if not omit_none:
                    out[key] = None
                continue
            out[key] = to_primitive(value)
        return out

    _ENCODERS[cls] = encode_dataclass
    return encode_dataclass


def to_primitive(obj: Any) -> Any:
    """Turn a dataclass (recursively) into JSON-ready Python values."""
    t = type(obj)
    if t is str or t is int or t is bool or obj is None:
        return obj
    if t is float:
        if not math.isfinite(obj):
            raise WireError(f"non-finite number {obj!r} cannot travel as JSON")
        return obj
    encoder = _ENCODERS.get(t)
    if encoder is not None:
        return encoder(obj)
    if t is tuple or t is list:
        return [to_primitive(v) for v in obj]
    if t is dict:
        return {str(k): to_primitive(v) for k, v in obj.items()}
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return _dataclass_encoder(t)(obj)
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, (list, tuple)):
        return [to_primitive(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_primitive(v) for k, v in obj.items()}
    item = getattr(obj, "item", None)  # a numpy scalar: travels as the plain Python number
    if callable(item) and getattr(obj, "shape", None) == ():
        return to_primitive(item())
    if isinstance(obj, numbers.Integral):
        return int(obj)
    if isinstance(obj, numbers.Real):
        return to_primitive(float(obj))
    if isinstance(obj, str):
        return str(obj)
    raise WireError(f"{t.__name__} cannot travel as JSON")


def dumps_std(value: Any) -> str:
    """Compact JSON by the standard library, refusing what is not finite: the fallback without orjson."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False)


def loads_std(text: str | bytes) -> Any:
    """JSON by the standard library, refusing NaN and infinities as orjson does: the fallback without orjson."""
    return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float)


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"number {text} is infinity when parsed as a double")
    return value


try:  # orjson, when installed, is several times faster both ways; the results are the same JSON
    import orjson

    def dumps(value: Any) -> str:
        return orjson.dumps(value).decode()

    def loads(text: str | bytes) -> Any:
        try:
            return orjson.loads(text)
        except orjson.JSONDecodeError as error:
            raise ValueError(str(error)) from None

except ImportError:  # pragma: no cover - exercised on machines without orjson
    dumps, loads = dumps_std, loads_std


def encode(obj: Any) -> str:
    """Compact JSON of a message dataclass (non-finite numbers are refused before this point)."""
    return dumps(to_primitive(obj))


# ----------------------------------------------------------------------------- decoding
def decode(cls: type[T], text: str | bytes, *, source: str = "", max_bytes: int = MAX_MESSAGE_BYTES) -> T:
    """Parse and validate ``text`` as a ``cls`` message; raises :class:`WireError`."""
    size = len(text)
    if size > max_bytes:
        raise WireError(f"message of {size} bytes exceeds the limit of {max_bytes}", source=source, type_name=cls.__name__)
    try:
        raw = loads(text)
    except (ValueError, RecursionError) as error:
        raise WireError(f"not valid JSON: {error}", source=source, type_name=cls.__name__) from None
    return from_primitive(cls, raw, source=source)


def parse_json(text: str | bytes, max_bytes: int = MAX_MESSAGE_BYTES) -> Any:
    """Parse JSON from another process (a typed message's ``*_json`` field): ValueError when it is
    larger than ``max_bytes``, not JSON, or holds NaN or infinity."""
    if len(text) > max_bytes:
        raise ValueError(f"{len(text)} bytes exceed the limit of {max_bytes}")
    try:
        value = loads(text)
    except RecursionError:
        raise ValueError("nested too deeply") from None
    except ValueError as error:
        raise ValueError(f"not valid JSON: {error}") from None
    try:
        _check_json_value(value, 0)
    except _Mismatch as error:
        raise ValueError(error.reason) from None
    return value


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed")


def from_primitive(cls: type[T], raw: Any, *, source: str = "") -> T:
    """Validate already-parsed JSON values as a ``cls`` message."""
    try:
        return _converter(cls)(raw)  # type: ignore[no-any-return]
    except _Mismatch as error:
        raise WireError(error.reason, source=source, type_name=cls.__name__, path=error.path) from None
    except RecursionError:
        raise WireError("nested too deeply", source=source, type_name=cls.__name__) from None


class _Mismatch(Exception):
    """A value that does not fit; the path is assembled on the way out, so the happy path pays nothing."""

    def __init__(self, reason: str, parts: list[str | int] | None = None) -> None:
        super().__init__(reason)
        self.reason = reason
        self.parts: list[str | int] = parts or []

    def inside(self, key: str | int) -> _Mismatch:
        self.parts.insert(0, key)
        return self

    @property
    def path(self) -> str:
        out = ""
        for part in self.parts:
            out = f"{out}[{part}]" if isinstance(part, int) else (f"{out}.{part}" if out else part)
        return out


def _describe(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


Converter = Callable[[Any], Any]


@lru_cache(maxsize=None)
def _converter(hint: Any) -> Converter:  # noqa: C901 - one dispatch over type forms, run once per type
    """Build (once per type) the function that validates and converts a JSON value for ``hint``."""
    if hint is Any:
        def convert_any(value: Any) -> Any:
            _check_json_value(value, 0)
            return value
        return convert_any
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return _dataclass_converter(hint)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        allowed = ", ".join(repr(m.value) for m in hint)

        def convert_enum(value: Any) -> Any:
            try:
                return hint(value)
            except ValueError:
                raise _Mismatch(f"{_describe(value)} is not one of {allowed}") from None
        return convert_enum
    origin = get_origin(hint)
    if origin is Literal:
        values = get_args(hint)
        text = ", ".join(repr(a) for a in values)

        def convert_literal(value: Any) -> Any:
            if type(value) is bool or value not in values:
                if not (type(value) is bool and any(v is value for v in values)):
                    raise _Mismatch(f"{_describe(value)} is not one of {text}")
            return value
        return convert_literal
    if origin in (Union, types.UnionType):
        return _union_converter(hint)
    if origin in (list, tuple):
        return _sequence_converter(hint, origin)
    if origin is dict:
        item = _converter((get_args(hint) or (str, Any))[1])

        def convert_dict(value: Any) -> Any:
            if type(value) is not dict:
                raise _Mismatch(f"expected an object, got {_describe(value)}")
            out = {}
            for k, v in value.items():
                try:
                    out[k] = item(v)
                except _Mismatch as error:
                    raise error.inside(k) from None
            return out
        return convert_dict
    return _scalar_converter(hint)


def _scalar_converter(hint: Any) -> Converter:
    if hint is type(None) or hint is None:
        def convert_none(value: Any) -> None:
            if value is not None:
                raise _Mismatch(f"expected null, got {_describe(value)}")
        return convert_none
    if hint is float:
        def convert_float(value: Any) -> float:
            t = type(value)
            if (t is not float and t is not int) or not math.isfinite(value):
                raise _Mismatch(f"expected a finite number, got {_describe(value)}")
            return float(value)
        return convert_float
    names = {bool: "true or false", int: "an integer", str: "a string"}
    if hint not in names:
        raise TypeError(f"unsupported field type {hint!r}")
    expected = names[hint]

    def convert_exact(value: Any) -> Any:
        if type(value) is not hint:
            raise _Mismatch(f"expected {expected}, got {_describe(value)}")
        return value
    return convert_exact


def _sequence_converter(hint: Any, origin: Any) -> Converter:
    args = get_args(hint)
    if origin is tuple and args and args[-1] is not Ellipsis:
        fixed = tuple(_converter(a) for a in args)

        def convert_fixed(value: Any) -> Any:
            if type(value) is not list:
                raise _Mismatch(f"expected a list, got {_describe(value)}")
            if len(value) != len(fixed):
                raise _Mismatch(f"expected {len(fixed)} items, got {len(value)}")
            return tuple(_item(c, v, i) for i, (c, v) in enumerate(zip(fixed, value)))
        return convert_fixed
    item = _converter(args[0] if args else Any)
    make = tuple if origin is tuple else list

    def convert_sequence(value: Any) -> Any:
        if type(value) is not list:
            raise _Mismatch(f"expected a list, got {_describe(value)}")
        try:
            return make([item(v) for v in value])
        except _Mismatch:
            for i, v in enumerate(value):  # find which item, for the message
                _item(item, v, i)
            raise
    return convert_sequence


def _item(convert: Converter, value: Any, index: int) -> Any:
    try:
        return convert(value)
    except _Mismatch as error:
        raise error.inside(index) from None


def _union_converter(hint: Any) -> Converter:
    args = get_args(hint)
    optional = type(None) in args
    members = [a for a in args if a is not type(None)]
    if is_tagged_union(hint):
        by_kind = {a.KIND: _converter(a) for a in members}
        kinds = ", ".join(sorted(by_kind))

        def convert_tagged(value: Any) -> Any:
            if value is None:
                if optional:
                    return None
                raise _Mismatch("is required (got null)")
            if type(value) is not dict:
                raise _Mismatch(f"expected an object with a 'kind', got {_describe(value)}")
            kind = value.get("kind")
            convert = by_kind.get(kind) if isinstance(kind, str) else None
            if convert is None:
                raise _Mismatch(f"{_describe(kind)} is not one of {kinds}", ["kind"])
            return convert(value)
        return convert_tagged
    converters = [_converter(m) for m in members]

    def convert_union(value: Any) -> Any:
        if value is None:
            if optional:
                return None
            raise _Mismatch("is required (got null)")
        errors = []
        for convert in converters:
            try:
                return convert(value)
            except _Mismatch as error:
                errors.append(error.reason)
        raise _Mismatch("; or ".join(errors))
    return convert_union


def _dataclass_converter(cls: type) -> Converter:
    plans = field_plan(cls)
    fields = [(p.key, p.name, p.required) for p in plans]
    known = {p.key for p in plans} | {"kind"}
    kind = getattr(cls, "KIND", None)
    lazy: dict[str, Converter] = {}  # built on first use: dataclasses may refer to each other

    def convert_dataclass(value: Any) -> Any:
        if type(value) is not dict:
            raise _Mismatch(f"expected an object for {cls.__name__}, got {_describe(value)}")
        for key in value:
            if key not in known:
                raise _Mismatch(f"unknown field in {cls.__name__}", [key])
        if isinstance(kind, str) and value.get("kind", kind) != kind:
            raise _Mismatch(f"expected {kind!r}, got {_describe(value.get('kind'))}", ["kind"])
        kwargs = {}
        for key, name, required in fields:
            if key in value:
                convert = lazy.get(key)
                if convert is None:
                    convert = lazy[key] = _converter(next(p.hint for p in plans if p.key == key))
                try:
                    kwargs[name] = convert(value[key])
                except _Mismatch as error:
                    raise error.inside(key) from None
            elif required:
                raise _Mismatch("is required", [key])
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as error:  # __post_init__ checks of the message itself
            raise _Mismatch(str(error)) from None
    return convert_dataclass


def _check_json_value(value: Any, depth: int) -> None:
    if depth > 64:
        raise _Mismatch("nested too deeply")
    if isinstance(value, _JSON_SCALARS):
        if isinstance(value, float) and not math.isfinite(value):
            raise _Mismatch("non-finite number")
        return
    if isinstance(value, list):
        for i, v in enumerate(value):
            try:
                _check_json_value(v, depth + 1)
            except _Mismatch as error:
                raise error.inside(i) from None
        return
    if isinstance(value, dict):
        for k, v in value.items():
            try:
                _check_json_value(v, depth + 1)
            except _Mismatch as error:
                raise error.inside(str(k)) from None
        return
    raise _Mismatch(f"not a JSON value: {_describe(value)}")

