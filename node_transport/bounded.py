"""Numeric node parameters declared with their range, so a value no cell could mean never starts a node.

Every transport's nodes declare parameters the same way (:meth:`Node.declare_parameter`); a
timeout of ``inf`` or a period of ``1e308`` is a perfectly typed double.  The ranges are those of
:mod:`core_functions.option_ranges`, the one table the CLI and the back ends check too.
"""
from __future__ import annotations

from core_functions.option_ranges import RangeError, bounds
from node_transport.port import Node, TransportError


def declare_bounded(
    node: Node, name: str, default: float | int, description: str, *, setting: str | None = None, scope: str = "",
    unset: float | None = None,
) -> float | int:
    """Declare a numeric parameter whose value must lie in the range of ``setting`` (default ``name``)
    as ``scope`` (a back end) reads it; ``unset``: a value outside the range that means "the back
    end's default" (KUKA RSI's ``silence`` 0.0), taken as it is.

    The range is added to the description, so ``ros2 param describe`` shows it; a value outside
    it is a TransportError naming the node, the parameter and the range, as a mistyped value is
    (a node's start-up ends with a usage error).
    """
    allowed = bounds(setting or name, scope)
    also = "" if unset is None else f" (or {unset:g}: the back end's default)"
    value = node.declare_parameter(name, default, f"{description}; range {allowed.describe()}{also}")
    if unset is not None and value == unset:
        return value
    try:
        checked = allowed.check(f"{node.fully_qualified_name}: parameter {name!r}", value)
    except RangeError as error:
        raise TransportError(str(error)) from None
    return int(checked) if isinstance(default, int) else checked
