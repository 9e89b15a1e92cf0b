"""The function library a cell runs with, handed to the engine and the machines by whoever starts them.

The engine needs the catalog (the functions an application may call, their parameters and their
contracts, paper Table 1) to read and check applications; a group machine needs that catalog and
one functions object to run them (paper Figure 5).  Neither needs to know which libraries exist:
the wiring (``cell_runner``) chooses them -- today ``app_functions``' -- and passes them in, so the
engine and the machines run any library built on :class:`~core_functions.functions.CoreFunctions`
and this package never imports a particular one.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from core_functions.catalog import Catalog
from core_functions.functions import CoreFunctions


@dataclass(frozen=True)
class FunctionLibrary:
    """How to get the catalog and the functions class of a choice of libraries (None: every library).

    A machine's ``libraries`` parameter names the choice; both callables refuse an unknown name
    or two libraries defining the same function with ``KeyError``/``ValueError``."""

    catalog: Callable[[Sequence[str] | None], Catalog]
    functions_class: Callable[[Sequence[str] | None], type[CoreFunctions]]
