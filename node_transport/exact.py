"""Whether a message dataclass is exactly what decoding its JSON would give, and copying its mutable parts.

In one process a message can travel as the very object its sender built instead of being encoded
and decoded again (:mod:`node_transport.carriage`).  That is the same as the wire only when
decoding the object's JSON (:func:`codec.from_primitive`) would give it back unchanged: every value
of exactly the type the decoder makes -- a float field holds a ``float``, not an ``int`` or a numpy
number; a tuple field a ``tuple``, not a list -- and within the decoder's limits: finite numbers,
strings a JSON encoder takes, 64-bit integers, :data:`codec.MAX_MESSAGE_BYTES`, the nesting depth
of :func:`codec.parse_json`.  :func:`exact` checks that, walking the value once; what it cannot
vouch for travels the long way and is decoded, or refused, by its receiver as before.

A decoded message holds dicts and lists of its own; :func:`copier` gives each receiver of a shared
object that too, so no receiver sees another's (or the sender's) later changes.
"""
from __future__ import annotations

import dataclasses
import enum
import math
import types
from collections.abc import Callable
from functools import lru_cache
from typing import Any, Literal, TypeVar, Union, get_args, get_origin

from node_transport.codec import MAX_MESSAGE_BYTES, field_plan, is_tagged_union

T = TypeVar("T")

INT_RANGE = (-(2**63), 2**64 - 1)  # the integers orjson encodes
JSON_DEPTH = 64  # the deepest JSON value codec.parse_json takes


class Walk:
    """What :func:`exact` found on its way: an upper bound of the value's JSON size in bytes, and
    whether it holds a dict or a list (a receiver must get its own copy of those)."""

    __slots__ = ("size", "mutable")

    def __init__(self) -> None:
        self.size = 0
        self.mutable = False


Exact = Callable[[Any, Walk], bool]


def exact(cls: type[Any], obj: Any) -> Walk | None:
    """The walk of ``obj`` when it is exactly the ``cls`` that decoding its JSON gives, else None."""
    walk = Walk()
    try:
        ok = checker(cls)(obj, walk)
    except RecursionError:
        return None
    return walk if ok and walk.size <= MAX_MESSAGE_BYTES else None


# ------------------------------------------------------------------------------- scalars
def _str(value: Any, walk: Walk) -> bool:
    if type(value) is not str or not (value.isascii() or _encodable(value)):
        return False
    walk.size += 6 * len(value) + 3  # every character escaped, the quotes, a separator
    return True


def _float(value: Any, walk: Walk) -> bool:
    walk.size += 26
    return type(value) is float and math.isfinite(value)


def _int(value: Any, walk: Walk) -> bool:
    walk.size += 22
    return type(value) is int and INT_RANGE[0] <= value <= INT_RANGE[1]


def _bool(value: Any, walk: Walk) -> bool:
    walk.size += 6
    return type(value) is bool


def _none(value: Any, walk: Walk) -> bool:
    walk.size += 5
    return value is None


def _never(value: Any, walk: Walk) -> bool:
    return False


def _json(value: Any, walk: Walk, depth: int = 0) -> bool:
    """A JSON value as the parser gives it: dicts with string keys, lists, plain scalars."""
    t = type(value)
    if t is str:
        return _str(value, walk)
    if t is float:
        return _float(value, walk)
    if t is int:
        return _int(value, walk)
    if t is bool or value is None:
        walk.size += 6
        return True
    if depth >= JSON_DEPTH:
        return False
    if t is list:
        walk.mutable = True
        walk.size += 2
        return all(_json(v, walk, depth + 1) for v in value)
    if t is dict:
        walk.mutable = True
        walk.size += 2
        return all(_str(k, walk) and _json(v, walk, depth + 1) for k, v in value.items())
    return False


_SCALARS: dict[Any, Exact] = {float: _float, int: _int, bool: _bool, str: _str, None: _none, type(None): _none}


# ------------------------------------------------------------------------------- checkers
@lru_cache(maxsize=None)
def checker(hint: Any) -> Exact:
    """The check (built once per type) that a value is exactly what decoding gives for ``hint``."""
    if hint is Any:
        return _json
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return _dataclass(hint)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return _enum(hint)
    origin = get_origin(hint)
    if origin is Literal:
        return _literal(get_args(hint))
    if origin in (Union, types.UnionType):
        return _union(hint)
    if origin in (list, tuple):
        return _sequence(hint, origin)
    if origin is dict:
        return _dict(hint)
    return _SCALARS.get(hint, _never)


def _enum(hint: type[enum.Enum]) -> Exact:
    width = 6 * max((len(str(m.value)) for m in hint), default=0) + 3

    def exact_enum(value: Any, walk: Walk) -> bool:
        walk.size += width
        return type(value) is hint
    return exact_enum


def _literal(values: tuple[Any, ...]) -> Exact:
    allowed = {(type(a), a) for a in values}  # True is not 1 here, as the decoder has it
    width = 6 * max(len(str(a)) for a in values) + 3

    def exact_literal(value: Any, walk: Walk) -> bool:
        walk.size += width
        try:
            return (type(value), value) in allowed
        except TypeError:  # unhashable
            return False
    return exact_literal


def _union(hint: Any) -> Exact:
    args = get_args(hint)
    optional = type(None) in args
    members = [a for a in args if a is not type(None)]
    if is_tagged_union(hint):
        by_type = {a: checker(a) for a in members}

        def exact_tagged(value: Any, walk: Walk) -> bool:
            if value is None:
                walk.size += 5
                return optional
            check = by_type.get(type(value))
            return check is not None and check(value, walk)
        return exact_tagged
    if len(members) != 1:  # which member the decoder picks depends on the value: not vouched for
        return _never
    check = checker(members[0])

    def exact_optional(value: Any, walk: Walk) -> bool:
        if value is None:
            walk.size += 5
            return optional
        return check(value, walk)
    return exact_optional


def _sequence(hint: Any, origin: Any) -> Exact:
    args = get_args(hint)
    if origin is tuple and args and args[-1] is not Ellipsis:
        fixed = tuple(checker(a) for a in args)

        def exact_fixed(value: Any, walk: Walk) -> bool:
            walk.size += 2
            return type(value) is tuple and len(value) == len(fixed) and all(c(v, walk) for c, v in zip(fixed, value))
        return exact_fixed
    check = checker(args[0] if args else Any)
    mutable = origin is list

    def exact_sequence(value: Any, walk: Walk) -> bool:
        if type(value) is not origin:
            return False
        if mutable:
            walk.mutable = True
        walk.size += 2
        return all(check(v, walk) for v in value)
    return exact_sequence


def _dict(hint: Any) -> Exact:
    key, item = get_args(hint) or (str, Any)
    if key is not str:
        return _never
    check = checker(item)

    def exact_dict(value: Any, walk: Walk) -> bool:
        if type(value) is not dict:
            return False
        walk.mutable = True
        walk.size += 2
        return all(_str(k, walk) and check(v, walk) for k, v in value.items())
    return exact_dict


def _dataclass(cls: type) -> Exact:
    """The check of a message dataclass, compiled here: it runs once per message on the hot path, so
    its scalar fields are checked inline, without a call per field, as dataclasses' own generated
    __init__ does, and a nested dataclass's compiled check is called directly.  A dataclass that
    refers to itself (while its check is being compiled) is checked through a wrapper compiled on
    first use."""
    if cls in _COMPILING:
        compiled: list[Exact] = []

        def exact_dataclass(value: Any, walk: Walk) -> bool:
            if not compiled:
                compiled.append(checker(cls))
            return compiled[0](value, walk)
        return exact_dataclass
    _COMPILING.add(cls)
    try:
        return _compile(cls)
    finally:
        _COMPILING.discard(cls)


_COMPILING: set[type] = set()  # the dataclasses whose checks are being compiled now


class _Source:
    """The lines of one generated check, and the objects its code refers to by name."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.names: dict[str, Any] = {"encodable": _encodable, "INT_MIN": INT_RANGE[0], "INT_MAX": INT_RANGE[1]}
        self.width = 16  # the braces and a "kind" tag
        self.depth = 0

    def name(self, obj: Any) -> str:
        key = f"n{len(self.names)}"
        self.names[key] = obj
        return key

    def scalar(self, x: str, hint: Any, pad: str) -> list[str] | None:
        """Inline lines that return False unless ``x`` is exact for a scalar ``hint`` (None: not a scalar)."""
        fail = "return False"
        if hint is str:
            return [f"{pad}if type({x}) is not str or not ({x}.isascii() or encodable({x})): {fail}",
                    f"{pad}size += 6 * len({x}) + 3"]
        if hint is float:  # x - x is NaN for infinities and NaN
            return [f"{pad}if type({x}) is not float or {x} - {x} != 0.0: {fail}", f"{pad}size += 26"]
        if hint is int:
            return [f"{pad}if type({x}) is not int or not INT_MIN <= {x} <= INT_MAX: {fail}", f"{pad}size += 22"]
        if hint is bool:
            return [f"{pad}if type({x}) is not bool: {fail}", f"{pad}size += 6"]
        if isinstance(hint, type) and issubclass(hint, enum.Enum):
            width = 6 * max((len(str(m.value)) for m in hint), default=0) + 3
            return [f"{pad}if type({x}) is not {self.name(hint)}: {fail}", f"{pad}size += {width}"]
        if get_origin(hint) is Literal and all(type(a) is str for a in get_args(hint)):
            width = 6 * max(len(a) for a in get_args(hint)) + 3
            return [f"{pad}if type({x}) is not str or {x} not in {self.name(frozenset(get_args(hint)))}: {fail}", f"{pad}size += {width}"]
        return None

    def field(self, x: str, hint: Any, pad: str) -> list[str]:
        """Lines that return False unless ``x`` is exact for ``hint``: inline where they can be."""
        inline = self.scalar(x, hint, pad)
        if inline is not None:
            return inline
        origin, args = get_origin(hint), get_args(hint)
        members = [a for a in args if a is not type(None)]
        if origin in (Union, types.UnionType) and len(members) == 1 and type(None) in args and not is_tagged_union(hint):
            inner = self.scalar(x, members[0], pad + "    ")
            if inner is not None:
                return [f"{pad}if {x} is None:", f"{pad}    size += 5", f"{pad}else:", *inner]
        if origin is tuple and len(args) == 2 and args[1] is Ellipsis:
            self.depth += 1
            item = f"i{self.depth}"
            inner = self.scalar(item, args[0], pad + "    ")
            if inner is not None:
                return [f"{pad}if type({x}) is not tuple: return False", f"{pad}size += 2", f"{pad}for {item} in {x}:", *inner]
        if origin in (Union, types.UnionType) and is_tagged_union(hint):  # as _union's exact_tagged, without its call
            by_type = self.name({a: checker(a) for a in members})
            none = [f"{pad}    size += 5"] if type(None) in args else [f"{pad}    return False"]
            return [
                f"{pad}if {x} is None:", *none, f"{pad}else:",
                f"{pad}    c = {by_type}.get(type({x}))",
                f"{pad}    if c is None or not c({x}, walk): return False",
            ]
        if origin is dict and len(args) == 2 and args[0] is str:  # as _dict's check, without a call per item
            self.depth += 1
            key, item = f"k{self.depth}", f"i{self.depth}"
            inner = self.scalar(item, args[1], pad + "    ") or [f"{pad}    if not {self.name(checker(args[1]))}({item}, walk): return False"]
            return [
                f"{pad}if type({x}) is not dict: return False", f"{pad}walk.mutable = True", f"{pad}size += 2",
                f"{pad}for {key}, {item} in {x}.items():",
                *self.scalar(key, str, pad + "    "),  # type: ignore[misc]
                *inner,
            ]
        return [f"{pad}if not {self.name(checker(hint))}({x}, walk): return False"]


def _compile(cls: type) -> Exact:
    source = _Source()
    body = [f"    if type(value) is not {source.name(cls)}: return False", "    size = 0"]
    for plan in field_plan(cls):
        source.width += len(plan.key) + 4  # the key, its quotes, colon and comma
        body.append(f"    v = value.{plan.name}")
        body.extend(source.field("v", plan.hint, "    "))
    body += [f"    walk.size += size + {source.width}", "    return True"]
    code = "\n".join(["def exact_message(value, walk):", *body])
    namespace = dict(source.names)
    exec(compile(code, f"<exact check of {cls.__name__}>", "exec"), namespace)  # noqa: S102 - our own generated code
    return namespace["exact_message"]  # type: ignore[no-any-return]


def _encodable(text: str) -> bool:
    try:
        text.encode()
    except UnicodeEncodeError:  # a lone surrogate: no JSON encoder takes it
        return False
    return True


# -------------------------------------------------------------------------------- copying
def copier(cls: type[T]) -> Callable[[T], T]:
    """A copy of a ``cls`` value (one :func:`exact` accepted) with every dict and list in it new
    and the rest shared, as immutable as what a receiver decodes."""
    copy = _copier(cls)
    return copy if copy is not None else _same


def _same(value: T) -> T:
    return value


def _copy_json(value: Any) -> Any:
    t = type(value)
    if t is dict:
        return {k: _copy_json(v) for k, v in value.items()}
    if t is list:
        return [_copy_json(v) for v in value]
    return value


@lru_cache(maxsize=None)
def _copier(hint: Any) -> Callable[[Any], Any] | None:
    """The copy for ``hint``; None when its values hold nothing mutable (wire types do not refer to themselves)."""
    if hint is Any:
        return _copy_json
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return _dataclass_copier(hint)
    origin = get_origin(hint)
    if origin in (Union, types.UnionType):
        by_type = {get_origin(a) or a: c for a in get_args(hint) if a is not type(None) and (c := _copier(a)) is not None}
        if not by_type:
            return None
        return lambda value: by_type[type(value)](value) if type(value) in by_type else value
    if origin in (list, tuple):
        return _sequence_copier(hint, origin)
    if origin is dict:
        item = _copier((get_args(hint) or (str, Any))[1])
        if item is None:
            return dict
        return lambda value: {k: item(v) for k, v in value.items()}
    return None


def _sequence_copier(hint: Any, origin: Any) -> Callable[[Any], Any] | None:
    args = [a for a in get_args(hint) if a is not Ellipsis] or [Any]
    items = [_copier(a) for a in args]
    if origin is tuple and len(args) > 1 and get_args(hint)[-1] is not Ellipsis:  # tuple[int, str]
        if all(c is None for c in items):
            return None
        fixed = [c or _same for c in items]
        return lambda value: tuple(c(v) for c, v in zip(fixed, value))
    item = items[0]
    if origin is tuple:
        return None if item is None else (lambda value: tuple(item(v) for v in value))
    return list if item is None else (lambda value: [item(v) for v in value])


def _dataclass_copier(cls: type) -> Callable[[Any], Any] | None:
    fields = [(p.name, c) for p in field_plan(cls) if (c := _copier(p.hint)) is not None]
    if not fields:
        return None
    if "__slots__" in cls.__dict__:
        def replace_dataclass(value: Any) -> Any:
            return dataclasses.replace(value, **{name: c(v) for name, c in fields if (v := getattr(value, name)) is not None})
        return replace_dataclass

    def copy_dataclass(value: Any) -> Any:
        """The same fields in a new object, its dicts and lists new: built as a copy, not through
        ``__init__`` (``dataclasses.replace``), whose checks the value passed when it was made."""
        new = object.__new__(cls)
        attrs = new.__dict__
        attrs.update(value.__dict__)
        for name, c in fields:
            v = attrs[name]
            if v is not None:
                attrs[name] = c(v)
        return new
    return copy_dataclass
