"""The function libraries this program ships (``app_functions``), in the form the engine and the machines take.

The engine and the machines are handed their library (:mod:`execution_engine.function_library`);
this is the one every command, node process and the studio hand them.
"""
from __future__ import annotations

from app_functions.registry import full_catalog, functions_class
from execution_engine.function_library import FunctionLibrary

APPLICATION_FUNCTIONS = FunctionLibrary(catalog=full_catalog, functions_class=functions_class)
