"""A stand-in for rclpy (7.1, ROS 2 Jazzy), for testing the ros transport without ROS 2.

It models what rclpy and the middleware really do where the adapter depends on it -- including
the parts that bit us on a real Jazzy -- not rclpy's internals.  One module per thing it fakes:

* ``ros_fake_context`` -- ``rclpy.init`` parses ``--ros-args`` as rcl does and refuses what rcl
  refuses, with rcl's exception types (``ros_fake_args``): parameter values typed by rcl's YAML
  rules (``off`` is a bool, ``0x10`` an int), ``--params-file`` sections matched to node names,
  ``--log-level``, ``-r __node:=``/``__ns:=`` renames;
* ``ros_fake_graph`` -- DDS discovery takes time: every publisher/subscription and client/service
  pair matches only ``GRAPH.match_delay`` wall seconds after both exist, and only when their QoS
  (``ros_fake_qos``) are compatible;
* ``ros_fake_topics`` -- nothing is delivered before the match (a volatile message published
  earlier is lost; a TRANSIENT_LOCAL history reaches the reader at the match);
  ``get_subscription_count`` / ``get_publisher_count`` count matches only; messages are delivered
  as copies (as DDS would);
* ``ros_fake_services`` -- ``service_is_ready`` counts matches only; ``call_async`` futures'
  done-callbacks run on an executor thread; ``destroy_service`` after which a response still to
  be sent raises ``InvalidHandle`` (as rclpy's ``send_response`` does);
* ``ros_fake_node`` and ``ros_fake_parameters`` -- ``Node`` with parameter overrides (and automatic
  declaration with a bare descriptor, the override's own type), ``declare_parameter``,
  ``set_descriptor`` (type checks, alternative value), ``describe_parameter``, descriptor ranges
  (``floating_point_range``/``integer_range``, refused with rclpy's reasons), pre-set and on-set callbacks;
  ``use_sim_time`` makes ``get_clock()`` follow ``/clock`` (``ros_fake_time``); ``get_logger()``
  writes to a ``/rosout`` record filtered by ``--log-level`` (``ros_fake_logging``); guard
  conditions (``ros_fake_callbacks``);
* ``ros_fake_executor`` -- executors whose ``spin`` runs callbacks on threads, honouring mutually
  exclusive groups over take + callback + response; an exception out of a callback ends ``spin``;
  and, like rclpy up to 7.1.11, ``shutdown(timeout_sec)`` returns at once without waiting for
  callbacks;
* ``ros_fake_action`` -- ``rclpy.action.ActionClient``: a goal is known from its goal response on,
  status entries of unknown goals are dropped, as rclpy's client does;
* ``ros_fake_msgs`` -- the interface packages' message and service classes.

This module puts them together as the modules ``rclpy`` and its interface packages:
``install(monkeypatch)`` puts the fake modules in ``sys.modules`` and returns the fake ``rclpy``;
the ``fake_rclpy`` fixture does it for one test.
"""
from __future__ import annotations

import sys
import types
from collections.abc import Iterator
from typing import Any

import pytest

from ros_fake_action import ActionClient
from ros_fake_callbacks import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from ros_fake_context import CONTEXT, ExternalShutdownException, SignalHandlerOptions, init, ok, remove_ros_args, shutdown
from ros_fake_executor import MultiThreadedExecutor
from ros_fake_graph import GRAPH
from ros_fake_logging import ROSOUT
from ros_fake_msgs import INTERFACE_MODULES
from ros_fake_node import FakeNode
from ros_fake_parameters import Parameter
from ros_fake_qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from ros_fake_services import Future
from ros_fake_topics import PublisherEventCallbacks, SubscriptionEventCallbacks


def _module(name: str, **attributes: Any) -> types.ModuleType:
    module = types.ModuleType(name)
    module.__dict__.update(attributes)
    return module


def install(monkeypatch: Any) -> types.ModuleType:
    """Put the fake rclpy and interface packages in ``sys.modules``; a fresh graph and context."""
    GRAPH.close()
    GRAPH.reset()
    CONTEXT.reset()
    ROSOUT.clear()
    rclpy = _module("rclpy", init=init, ok=ok, shutdown=shutdown, graph=lambda: GRAPH, context=lambda: CONTEXT)
    submodules = {
        "rclpy.node": _module("rclpy.node", Node=FakeNode),
        "rclpy.executors": _module(
            "rclpy.executors", MultiThreadedExecutor=MultiThreadedExecutor, ExternalShutdownException=ExternalShutdownException
        ),
        "rclpy.callback_groups": _module(
            "rclpy.callback_groups", MutuallyExclusiveCallbackGroup=MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup=ReentrantCallbackGroup
        ),
        "rclpy.parameter": _module("rclpy.parameter", Parameter=Parameter),
        "rclpy.qos": _module(
            "rclpy.qos", QoSProfile=QoSProfile, ReliabilityPolicy=ReliabilityPolicy, DurabilityPolicy=DurabilityPolicy, HistoryPolicy=HistoryPolicy
        ),
        "rclpy.signals": _module("rclpy.signals", SignalHandlerOptions=SignalHandlerOptions),
        "rclpy.utilities": _module("rclpy.utilities", remove_ros_args=remove_ros_args),
        "rclpy.task": _module("rclpy.task", Future=Future),
        "rclpy.event_handler": _module(
            "rclpy.event_handler", PublisherEventCallbacks=PublisherEventCallbacks, SubscriptionEventCallbacks=SubscriptionEventCallbacks
        ),
        "rclpy.action": _module("rclpy.action", ActionClient=ActionClient),
    }
    for name, module in submodules.items():
        setattr(rclpy, name.split(".", 1)[1], module)
        monkeypatch.setitem(sys.modules, name, module)
    monkeypatch.setitem(sys.modules, "rclpy", rclpy)
    for module_name, classes in INTERFACE_MODULES.items():
        package = module_name.split(".")[0]
        monkeypatch.setitem(sys.modules, package, _module(package))
        monkeypatch.setitem(sys.modules, module_name, _module(module_name, **classes))
    return rclpy


@pytest.fixture
def fake_rclpy(monkeypatch: pytest.MonkeyPatch) -> Iterator[types.ModuleType]:
    """The fake rclpy installed for one test (import this fixture into a test module)."""
    yield install(monkeypatch)
    GRAPH.close()
