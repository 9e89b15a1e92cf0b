"""Dataclass <-> JSON coding with validation: the contract of every JSON message on the wire.

Structured messages travel as JSON inside ``std_msgs/String``.  Whatever arrives is input from
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
class _FieldPlan:
    name: str
    key: str
    hint: Any
    required: bool
    omit_none: bool  # default is None: a None value is left out of the JSON


@lru_cache(maxsize=None)
def _plan(cls: type) -> tuple[_FieldPlan, ...]:
    hints = typing.get_type_hints(cls)
    plans = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        plans.append(_FieldPlan(f.name, f.metadata.get("json", f.name), hints[f.name], required, f.default is None))
    return tuple(plans)


def _is_tagged_union(hint: Any) -> bool:
    args = get_args(hint)
    members = [a for a in args if a is not type(None)]
    return (
        len(members) > 1
        and all(dataclasses.is_dataclass(a) and isinstance(getattr(a, "KIND", None), str) for a in members)
    )


# ----------------------------------------------------------------------------- encoding
def to_primitive(obj: Any) -> Any:
    """Turn a dataclass (recursively) into JSON-ready Python values."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out: dict[str, Any] = {}
        kind = getattr(type(obj), "KIND", None)
        if isinstance(kind, str):
            out["kind"] = kind
        for plan in _plan(type(obj)):
            value = getattr(obj, plan.name)
            if value is None and plan.omit_none:
                continue
            out[plan.key] = to_primitive(value)
        return out
    if isinstance(obj, enum.Enum):
        return obj.value
    if isinstance(obj, (list, tuple)):
        return [to_primitive(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_primitive(v) for k, v in obj.items()}
    if isinstance(obj, float) and not math.isfinite(obj):
        raise WireError(f"non-finite number {obj!r} cannot travel as JSON")
    return obj


def encode(obj: Any) -> str:
    """Compact JSON of a message dataclass."""
    return json.dumps(to_primitive(obj), separators=(",", ":"), allow_nan=False)


# ----------------------------------------------------------------------------- decoding
def decode(cls: type[T], text: str | bytes, *, source: str = "", max_bytes: int = MAX_MESSAGE_BYTES) -> T:
    """Parse and validate ``text`` as a ``cls`` message; raises :class:`WireError`."""
    size = len(text)
    if size > max_bytes:
        raise WireError(f"message of {size} bytes exceeds the limit of {max_bytes}", source=source, type_name=cls.__name__)
    try:
        raw = json.loads(text, parse_constant=_reject_constant)
    except (ValueError, RecursionError) as error:
        raise WireError(f"not valid JSON: {error}", source=source, type_name=cls.__name__) from None
    return from_primitive(cls, raw, source=source)


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not allowed")


def from_primitive(cls: type[T], raw: Any, *, source: str = "") -> T:
    """Validate already-parsed JSON values as a ``cls`` message."""
    try:
        return _convert(cls, raw, "")
    except _Mismatch as error:
        raise WireError(error.reason, source=source, type_name=cls.__name__, path=error.path) from None


class _Mismatch(Exception):
    def __init__(self, path: str, reason: str) -> None:
        super().__init__(reason)
        self.path = path
        self.reason = reason


def _join(path: str, key: str | int) -> str:
    if isinstance(key, int):
        return f"{path}[{key}]"
    return f"{path}.{key}" if path else key


def _describe(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _convert(hint: Any, value: Any, path: str) -> Any:  # noqa: C901 - one dispatch over type forms
    if hint is Any:
        _check_json_value(value, path)
        return value
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return _convert_dataclass(hint, value, path)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        try:
            return hint(value)
        except ValueError:
            allowed = ", ".join(repr(m.value) for m in hint)
            raise _Mismatch(path, f"{_describe(value)} is not one of {allowed}") from None
    origin = get_origin(hint)
    if origin is Literal:
        allowed_values = get_args(hint)
        if value not in allowed_values or type(value) is bool and True not in allowed_values and False not in allowed_values:
            raise _Mismatch(path, f"{_describe(value)} is not one of {', '.join(repr(a) for a in allowed_values)}")
        return value
    if origin in (Union, types.UnionType):
        return _convert_union(hint, value, path)
    if origin in (list, tuple):
        args = get_args(hint)
        if not isinstance(value, list):
            raise _Mismatch(path, f"expected a list, got {_describe(value)}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise _Mismatch(path, f"expected {len(args)} items, got {len(value)}")
            return tuple(_convert(a, v, _join(path, i)) for i, (a, v) in enumerate(zip(args, value)))
        item = args[0] if args else Any
        items = [_convert(item, v, _join(path, i)) for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        key_type, item = get_args(hint) or (str, Any)
        if not isinstance(value, dict):
            raise _Mismatch(path, f"expected an object, got {_describe(value)}")
        return {k: _convert(item, v, _join(path, k)) for k, v in value.items()}
    return _convert_scalar(hint, value, path)


def _convert_scalar(hint: Any, value: Any, path: str) -> Any:
    if hint is type(None) or hint is None:
        if value is not None:
            raise _Mismatch(path, f"expected null, got {_describe(value)}")
        return None
    if hint is bool:
        if type(value) is not bool:
            raise _Mismatch(path, f"expected true or false, got {_describe(value)}")
        return value
    if hint is int:
        if type(value) is not int:
            raise _Mismatch(path, f"expected an integer, got {_describe(value)}")
        return value
    if hint is float:
        if type(value) not in (int, float) or not math.isfinite(value):
            raise _Mismatch(path, f"expected a finite number, got {_describe(value)}")
        return float(value)
    if hint is str:
        if type(value) is not str:
            raise _Mismatch(path, f"expected a string, got {_describe(value)}")
        return value
    raise _Mismatch(path, f"unsupported field type {hint!r}")


def _convert_union(hint: Any, value: Any, path: str) -> Any:
    args = get_args(hint)
    if value is None:
        if type(None) in args:
            return None
        raise _Mismatch(path, "is required (got null)")
    members = [a for a in args if a is not type(None)]
    if _is_tagged_union(hint):
        if not isinstance(value, dict):
            raise _Mismatch(path, f"expected an object with a 'kind', got {_describe(value)}")
        kind = value.get("kind")
        by_kind = {a.KIND: a for a in members}
        if kind not in by_kind:
            raise _Mismatch(_join(path, "kind"), f"{_describe(kind)} is not one of {', '.join(sorted(by_kind))}")
        return _convert_dataclass(by_kind[kind], value, path)
    if len(members) == 1:
        return _convert(members[0], value, path)
    errors = []
    for member in members:
        try:
            return _convert(member, value, path)
        except _Mismatch as error:
            errors.append(error.reason)
    raise _Mismatch(path, "; or ".join(errors))


def _convert_dataclass(cls: type, value: Any, path: str) -> Any:
    if not isinstance(value, dict):
        raise _Mismatch(path, f"expected an object for {cls.__name__}, got {_describe(value)}")
    plans = _plan(cls)
    known = {p.key for p in plans} | {"kind"}
    unknown = [k for k in value if k not in known]
    if unknown:
        raise _Mismatch(_join(path, unknown[0]), f"unknown field in {cls.__name__}")
    kind = getattr(cls, "KIND", None)
    if isinstance(kind, str) and value.get("kind", kind) != kind:
        raise _Mismatch(_join(path, "kind"), f"expected {kind!r}, got {_describe(value.get('kind'))}")
    kwargs = {}
    for plan in plans:
        if plan.key in value:
            kwargs[plan.name] = _convert(plan.hint, value[plan.key], _join(path, plan.key))
        elif plan.required:
            raise _Mismatch(_join(path, plan.key), "is required")
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as error:  # __post_init__ checks of the message itself
        raise _Mismatch(path, str(error)) from None


def _check_json_value(value: Any, path: str, depth: int = 0) -> None:
    if depth > 64:
        raise _Mismatch(path, "nested too deeply")
    if isinstance(value, _JSON_SCALARS):
        if isinstance(value, float) and not math.isfinite(value):
            raise _Mismatch(path, "non-finite number")
        return
    if isinstance(value, list):
        for i, v in enumerate(value):
            _check_json_value(v, _join(path, i), depth + 1)
        return
    if isinstance(value, dict):
        for k, v in value.items():
            _check_json_value(v, _join(path, str(k)), depth + 1)
        return
    raise _Mismatch(path, f"not a JSON value: {_describe(value)}")


def decoder(cls: type[T], *, source: str = "") -> Callable[[str], T]:
    """A one-argument decoder bound to a message type and a source, for subscription callbacks."""
    return lambda text: decode(cls, text, source=source)
