"""A small, typed, asyncio SMACH: states with declared outcomes, containers checked when built.

The group machine is built from these pieces; they know nothing of robots.
"""
from execution_engine.smach.container import HISTORY, ConsistencyError, StateMachine
from execution_engine.smach.introspection import MachineObserver, StructureInfo, TransitionRecord
from execution_engine.smach.state import CallbackState, State
from execution_engine.smach.userdata import UserData

__all__ = [
    "HISTORY",
    "CallbackState",
    "ConsistencyError",
    "MachineObserver",
    "State",
    "StateMachine",
    "StructureInfo",
    "TransitionRecord",
    "UserData",
]
