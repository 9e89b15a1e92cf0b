"""Execution engine: application model, engine, SMACH-style group machines, transports and CLI.

Kept free of imports so that ``robot_bridges`` can use the transport port and the clock
(``node_transport``, ``node_transport.clock``) without loading the engine.
"""
