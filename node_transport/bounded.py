"""Numeric node parameters declared with their range, so a value no cell could mean never starts a node.

Every transport's nodes declare parameters the same way (:meth:`Node.declare_parameter`); a
timeout of ``inf`` or a period of ``1e308`` is a perfectly typed double.  The ranges are those of
:mod:`core_functions.option_ranges`, the one table the CLI and the back ends check too.  Each
parameter carries its range the ROS way as well (:class:`~node_transport.parameters.NumericRange` in
its descriptor), so ``ros2 param describe`` prints its Min and Max and rclpy refuses a value outside it.
"""
from __future__ import annotations

from core_functions.option_ranges import Range, RangeError, bounds
from node_transport.parameters import NumericRange, ParameterValue
from node_transport.port import Node, TransportError


def ros_range(allowed: Range, unset: float | None = None) -> NumericRange | None:
    """``allowed`` as a ROS parameter range, or None where a ROS range cannot say it.

    A setting that takes only some values of its interval (KUKA RSI's ``cycle``: 4 or 12 ms) is a range
    with a step when they are evenly spaced from its lower to its upper end (4 to 12 step 8), as
    rcl_interfaces defines a step; a setting whose ``unset`` value lies outside its range (RSI's ``silence``
    0.0, "the back end's default") carries none: rclpy refuses to declare a parameter whose value lies
    outside its descriptor's range, and a range widened to admit the special value would show values
    as allowed that the node refuses.  Such a parameter shows its range in its description only."""
    if unset is not None and not allowed.contains(unset):
        return None
    step = 0.0
    if allowed.choices:
        values = sorted(allowed.choices)
        gaps = {b - a for a, b in zip(values, values[1:])}
        if values[0] != allowed.lower or values[-1] != allowed.upper or len(gaps) > 1:
            return None
        step = gaps.pop() if gaps else 0.0
    elif allowed.integer:
        step = 1.0  # a whole-number setting declared as a double: whole numbers from the lower end
    return NumericRange(allowed.lower, allowed.upper, step)


def declare_bounded(
    node: Node, name: str, default: float | int, description: str, *, setting: str | None = None, scope: str = "",
    unset: float | None = None,
) -> float | int:
    """Declare a numeric parameter whose value must lie in the range of ``setting`` (default ``name``)
    as ``scope`` (a back end) reads it; ``unset``: a value outside the range that means "the back
    end's default" (KUKA RSI's ``silence`` 0.0), taken as it is.

    The range goes into the parameter's descriptor (:func:`ros_range`) and its description. A value
    outside it is a TransportError naming the node, the parameter and the range in the project's words,
    checked before the transport declares it (rclpy would refuse it too, in its own words), as a
    mistyped value is (a node's start-up ends with a usage error).
    """
    allowed = bounds(setting or name, scope)
    also = "" if unset is None else f" (or {unset:g}: the back end's default)"
    value: ParameterValue = node.initial_parameter(name, default)
    if unset is None or value != unset:
        try:
            allowed.check(f"{node.fully_qualified_name}: parameter {name!r}", value)
        except RangeError as error:
            raise TransportError(str(error)) from None
    value = node.declare_parameter(name, default, f"{description}; range {allowed.describe()}{also}", ros_range(allowed, unset))
    assert isinstance(value, (int, float))  # checked above: a number in its range (or the unset value)
    return int(value) if isinstance(default, int) else float(value)
