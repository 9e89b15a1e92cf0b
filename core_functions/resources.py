"""Find the package's data files (XSD schemas, example applications, cells) wherever it runs from.

The same code runs from a source checkout (``pip install -e``, tests), from a pip install
(``<prefix>/share/dual_arm_executive``) and from a colcon install (the ament index).  Looking in a
fixed order, and saying where it looked when nothing is found, keeps "schema not found" errors
diagnosable instead of silently picking a stale copy.
"""
from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from pathlib import Path

PACKAGE = "dual_arm_executive"
ENV_VAR = "DUAL_ARM_EXECUTIVE_SHARE"

# The source tree: this file is <root>/execution_engine/resources.py, data lives in <root>/apps_xml.
_SOURCE_ROOT = Path(__file__).resolve().parent.parent


def share_roots() -> Iterator[Path]:
    """Candidate share directories, most specific first."""
    override = os.environ.get(ENV_VAR)
    if override:
        yield Path(override)
    yield _SOURCE_ROOT
    yield Path(sys.prefix) / "share" / PACKAGE
    try:
        # optional: ament_index_python is there only in a ROS 2 environment (the installed package's share folder)
        from ament_index_python.packages import get_package_share_directory  # type: ignore[import-not-found]
    except ImportError:
        return
    try:
        yield Path(get_package_share_directory(PACKAGE))
    except (LookupError, ValueError, OSError):
        return


def share_path(*parts: str) -> Path:
    """The first existing ``<share root>/<parts...>``; FileNotFoundError lists every place tried."""
    tried: list[str] = []
    for root in share_roots():
        candidate = root.joinpath(*parts)
        if candidate.exists():
            return candidate
        tried.append(str(candidate))
    raise FileNotFoundError(f"{'/'.join(parts)} not found; looked in: {', '.join(tried)}")
