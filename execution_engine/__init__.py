"""The execution engine: the application model, the engine, the SMACH-style group machines, the recorder and checkpoints.

It works over the transport port (``node_transport``) with any function library handed to it
(:mod:`execution_engine.function_library`); what starts it -- the command line, the node
processes, the dry run -- is ``cell_runner``'s.  ``python -m execution_engine`` is the program's
entry (``__main__.py``), which composes the command line with the operator station.
"""
