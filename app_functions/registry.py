"""Which function libraries exist, the catalog built from them, and the class a machine instantiates.

A group machine has one functions instance (paper Figure 5).  So that an application may call
functions from several libraries, the machine's class combines every library chosen (all by
default) by multiple inheritance -- they all derive from CoreFunctions, and the catalog refuses
two libraries defining the same function name, so the combination is unambiguous.
"""
from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

from app_functions.focus_approach import FocusApproach
from app_functions.rivet_installation import RivetInstallation
from core_functions.catalog import Catalog
from core_functions.functions import CoreFunctions

LIBRARIES: dict[str, type[CoreFunctions]] = {
    "core": CoreFunctions,
    "rivet_installation": RivetInstallation,
    "focus_approach": FocusApproach,
}


def _chosen(libraries: Sequence[str] | None) -> dict[str, type[CoreFunctions]]:
    if libraries is None:
        return dict(LIBRARIES)
    unknown = [name for name in libraries if name not in LIBRARIES]
    if unknown:
        raise KeyError(f"unknown function libraries {unknown} (known: {', '.join(LIBRARIES)})")
    return {"core": CoreFunctions, **{name: LIBRARIES[name] for name in libraries}}


@lru_cache(maxsize=None)
def catalog_of(libraries: tuple[str, ...] | None) -> Catalog:
    """The catalog of ``libraries`` (None: every library), built once; ``catalog_of.cache_clear()`` after
    :data:`LIBRARIES` changed (a library added at run time) builds it again."""
    return Catalog.from_classes(_chosen(libraries))


def full_catalog(libraries: Sequence[str] | None = None) -> Catalog:
    """The catalog of ``libraries`` (default: every library) plus the core functions."""
    return catalog_of(None if libraries is None else tuple(libraries))


def functions_class(libraries: Sequence[str] | None = None) -> type[CoreFunctions]:
    """One class offering every function of ``libraries`` (default: all)."""
    full_catalog(libraries)  # refuses clashing libraries before a class is made
    bases = tuple(cls for name, cls in _chosen(libraries).items() if name != "core")
    if not bases:
        return CoreFunctions
    if len(bases) == 1:
        return bases[0]
    return type("ApplicationFunctions", bases, {"__doc__": "Functions of: " + ", ".join(c.__name__ for c in bases)})
