"""``python -m execution_engine``: see :mod:`execution_engine.cli`."""
import os
import sys

from execution_engine.cli import main

try:
    sys.exit(main())
except BrokenPipeError:  # output piped into head & co: not an error of ours
    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    sys.exit(0)
