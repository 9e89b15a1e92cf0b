"""Execution engine: application model, engine, SMACH-style group machines, transports and CLI.

Kept free of imports so that ``robot_bridges`` can use the transport port and the clock
(``execution_engine.transport``, ``execution_engine.clock``) without loading the engine.
"""
