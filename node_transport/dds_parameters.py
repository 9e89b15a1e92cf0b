"""``ros2 param`` on a node of the DDS transport: the six rcl parameter services its client waits for.

rclpy serves ``~/set_parameters`` and its siblings on every node by itself; the DDS transport has no rcl, so a node
whose code lets a parameter change while it runs (:meth:`Node.changeable_parameter`: the engine's ``speed_override``)
serves them here, with the types of ``rcl_interfaces`` (copied in ``interfaces/ros2_jazzy``), so ``ros2 param set
/execution_engine speed_override 50`` from a ROS install reaches it as it would reach an rclpy node.  A change is
checked as the rclpy adapter checks it (:meth:`Node.check_parameter`: the declared type, the parameter's own check)
and refused with the reason in the result; every other parameter was read at start-up and is refused so.  ``list``,
``get``, ``describe`` (the description; a numeric parameter's range as rclpy's descriptor carries it, in
``floating_point_range`` or ``integer_range``, so ``ros2 param describe`` prints its Min and Max; read-only for the
parameters read at start-up) and the types answer as rclpy's would; a value outside the range is refused with
rclpy's own reason (:class:`~node_transport.parameters.NumericRange`); an atomic set takes every value or none.
"""
from __future__ import annotations

from typing import Any

from node_transport import mirrors
from node_transport.parameters import ParameterValue, descriptor_range
from node_transport.port import Node, ServiceServer

SetParameters = mirrors.service("rcl_interfaces/srv/SetParameters")
SetParametersAtomically = mirrors.service("rcl_interfaces/srv/SetParametersAtomically")
GetParameters = mirrors.service("rcl_interfaces/srv/GetParameters")
GetParameterTypes = mirrors.service("rcl_interfaces/srv/GetParameterTypes")
ListParameters = mirrors.service("rcl_interfaces/srv/ListParameters")
DescribeParameters = mirrors.service("rcl_interfaces/srv/DescribeParameters")
ParameterValueMsg = mirrors.mirror("rcl_interfaces/msg/ParameterValue")
SetParametersResult = mirrors.mirror("rcl_interfaces/msg/SetParametersResult")
ListParametersResult = mirrors.mirror("rcl_interfaces/msg/ListParametersResult")
ParameterDescriptor = mirrors.mirror("rcl_interfaces/msg/ParameterDescriptor")
FloatingPointRange = mirrors.mirror("rcl_interfaces/msg/FloatingPointRange")
IntegerRange = mirrors.mirror("rcl_interfaces/msg/IntegerRange")

#: rcl_interfaces/ParameterType: the field of a ParameterValue that holds a value of each type.
_FIELDS = {1: "bool_value", 2: "integer_value", 3: "double_value", 4: "string_value",
           6: "bool_array_value", 7: "integer_array_value", 8: "double_array_value", 9: "string_array_value"}


def value_of(message: Any) -> ParameterValue | None:
    """The value a ParameterValue carries (None: not set, or a byte array, which no parameter of ours takes)."""
    field = _FIELDS.get(int(message.type))
    if field is None:
        return None
    value = getattr(message, field)
    return list(value) if isinstance(value, (list, tuple)) else value  # type: ignore[no-any-return]


def message_of(value: ParameterValue | None) -> Any:
    """``value`` as a ParameterValue (type 0: not set)."""
    if value is None:
        return ParameterValueMsg(type=0)
    if isinstance(value, bool):
        return ParameterValueMsg(type=1, bool_value=value)
    if isinstance(value, int):
        return ParameterValueMsg(type=2, integer_value=value)
    if isinstance(value, float):
        return ParameterValueMsg(type=3, double_value=value)
    if isinstance(value, str):
        return ParameterValueMsg(type=4, string_value=value)
    kinds = {type(v) for v in value}
    code = 6 if kinds == {bool} else 7 if kinds == {int} else 8 if kinds == {float} else 9
    return ParameterValueMsg(**{"type": code, _FIELDS[code]: tuple(value)})


def checked(node: Node, parameter: Any) -> tuple[ParameterValue | None, str]:
    """A requested change as the node would take it, or (None, why not)."""
    value = value_of(parameter.value)
    if parameter.name not in node.declared_parameters():
        return None, f"parameter {parameter.name!r} is not declared by {node.fully_qualified_name}"
    if value is None:
        return None, f"parameter {parameter.name!r}: a value of type not set or byte array"
    return node.check_parameter(parameter.name, value)


def serve(node: Node) -> list[ServiceServer]:
    """The node's six parameter services, as rclpy names them."""

    async def set_parameters(request: Any) -> Any:
        results = []
        for parameter in request.parameters:
            value, refusal = checked(node, parameter)
            if value is not None:
                node.apply_parameter(parameter.name, value)
            results.append(SetParametersResult(successful=value is not None, reason=refusal))
        return SetParameters.Response(results=tuple(results))

    async def set_atomically(request: Any) -> Any:
        values = [(parameter.name, *checked(node, parameter)) for parameter in request.parameters]
        refused = [refusal for _, value, refusal in values if value is None]
        if refused:
            return SetParametersAtomically.Response(result=SetParametersResult(successful=False, reason="; ".join(refused)))
        for name, value, _ in values:
            node.apply_parameter(name, value)  # type: ignore[arg-type] - checked above
        return SetParametersAtomically.Response(result=SetParametersResult(successful=True, reason=""))

    async def get_parameters(request: Any) -> Any:
        declared = node.declared_parameters()
        return GetParameters.Response(values=tuple(message_of(declared.get(name)) for name in request.names))

    async def get_types(request: Any) -> Any:
        declared = node.declared_parameters()
        return GetParameterTypes.Response(types=tuple(int(message_of(declared.get(name)).type) for name in request.names))

    async def list_parameters(request: Any) -> Any:
        names = sorted(n for n in node.declared_parameters() if not request.prefixes or any(n.startswith(p) for p in request.prefixes))
        return ListParameters.Response(result=ListParametersResult(names=tuple(names), prefixes=()))

    async def describe(request: Any) -> Any:
        declared = node.declared_parameters()
        return DescribeParameters.Response(descriptors=tuple(
            ParameterDescriptor(name=name, type=int(message_of(declared.get(name)).type), description=node.descriptions.get(name, ""),
                                read_only=name in declared and not node.changeable(name), **descriptor_range(node.ranges.get(name), FloatingPointRange, IntegerRange))
            for name in request.names
        ))

    services = (
        (SetParameters, "set_parameters", set_parameters), (SetParametersAtomically, "set_parameters_atomically", set_atomically),
        (GetParameters, "get_parameters", get_parameters), (GetParameterTypes, "get_parameter_types", get_types),
        (ListParameters, "list_parameters", list_parameters), (DescribeParameters, "describe_parameters", describe),
    )
    return [node.create_service(kind, f"~/{name}", handler) for kind, name, handler in services]
