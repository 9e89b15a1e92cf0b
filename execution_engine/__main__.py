"""``python -m execution_engine``: the program's entry (see :mod:`operator_station.program`).

An entry composes every layer and nothing imports it, so it may import from the top: the command
line of ``cell_runner`` with the operator station's ``studio``.
"""
import os
import sys

from operator_station.program import main

try:
    sys.exit(main())
except BrokenPipeError:  # output piped into head & co: not an error of ours
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    sys.exit(0)
