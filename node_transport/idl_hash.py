"""ROS 2 type hashes (``RIHS01_<sha256>``) of interface files, as rosidl computes them since Iron.

rmw puts ``typehash=RIHS01_...;`` in the user data of every reader and writer; Jazzy's tools
warn about an endpoint without one and show its type hash as INVALID.  The hash is SHA-256 over a
fixed JSON rendering of the type's description and of every type it refers to (sorted by name),
field by field: name, type id (``type_description_interfaces/FieldType``), array capacity, string
capacity, nested type name.  Default values do not count.
"""
from __future__ import annotations

import hashlib
import json
from typing import Any

from node_transport.idl import FieldSpec, InterfaceRegistry

_BASE_IDS = {
    "nested": 1, "int8": 2, "uint8": 3, "char": 3, "int16": 4, "uint16": 5, "int32": 6, "uint32": 7,
    "int64": 8, "uint64": 9, "float32": 10, "float64": 11, "bool": 15, "byte": 16, "string": 17,
}
_BOUNDED_STRING = 21
_ARRAY, _BOUNDED_SEQUENCE, _UNBOUNDED_SEQUENCE = 48, 96, 144


def _field_type(spec: FieldSpec) -> dict[str, Any]:
    nested = "/" in spec.base
    base = _BASE_IDS["nested" if nested else spec.base]
    if spec.base == "string" and spec.string_bound:
        base = _BOUNDED_STRING
    capacity = 0
    if spec.array is None:
        type_id = base
    elif spec.array == "":
        type_id = base + _UNBOUNDED_SEQUENCE
    elif spec.array.startswith("<="):
        type_id, capacity = base + _BOUNDED_SEQUENCE, int(spec.array[2:])
    else:
        type_id, capacity = base + _ARRAY, int(spec.array)
    return {
        "type_id": type_id,
        "capacity": capacity,
        "string_capacity": spec.string_bound or 0,
        "nested_type_name": spec.base if nested else "",
    }


def _description(registry: InterfaceRegistry, ros_type: str) -> dict[str, Any]:
    spec = registry.spec(ros_type)
    return {"type_name": ros_type, "fields": [{"name": f.name, "type": _field_type(f)} for f in spec.fields]}


def type_hash(registry: InterfaceRegistry, ros_type: str) -> str:
    """``RIHS01_...`` of ``pkg/msg/Name`` or of a service part ``pkg/srv/Name_Request``."""
    main = _description(registry, ros_type)
    referenced: dict[str, dict[str, Any]] = {}
    queue = [f["type"]["nested_type_name"] for f in main["fields"] if f["type"]["nested_type_name"]]
    while queue:
        name = queue.pop()
        if name in referenced:
            continue
        referenced[name] = _description(registry, name)
        queue.extend(f["type"]["nested_type_name"] for f in referenced[name]["fields"] if f["type"]["nested_type_name"])
    document = {"type_description": main, "referenced_type_descriptions": [referenced[n] for n in sorted(referenced)]}
    text = json.dumps(document, ensure_ascii=True, allow_nan=False, indent=None, separators=(", ", ": "), sort_keys=False)
    return "RIHS01_" + hashlib.sha256(text.encode("utf-8")).hexdigest()


def type_hash_user_data(registry: InterfaceRegistry, ros_type: str) -> bytes:
    """The ``typehash=...;`` user data rmw gives an endpoint of ``ros_type``."""
    return f"typehash={type_hash(registry, ros_type)};".encode()
