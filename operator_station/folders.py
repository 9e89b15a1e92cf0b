"""The folders the page may open and save applications in, and the check every path it names goes through.

The page names files by text; whoever holds a session could otherwise read any ``.xml`` on the
computer or write one anywhere (``../``, an absolute path, a symbolic link pointing out).  A
path is resolved first -- every symbolic link followed, ``..`` taken out -- and then must lie
inside one of the station's folders (the folder ``studio`` was started in, and the folder of
the application it was started with), themselves resolved the same way.  Opening reads the
resolved file; saving replaces the resolved file (a temporary file beside it, then a rename),
so a link swapped in after the check is replaced, not followed.
"""
from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any


class Folders:
    """The station's folders, resolved once."""

    def __init__(self, roots: Iterable[Path]) -> None:
        self.roots: tuple[Path, ...] = tuple(dict.fromkeys(root.resolve() for root in roots))
        if not self.roots:
            raise ValueError("a station needs at least one folder")

    @property
    def root(self) -> Path:
        """The first folder: relative paths are taken from it."""
        return self.roots[0]

    def resolve(self, text: Any) -> Path:
        """The application file ``text`` names, resolved and inside a folder; ValueError (one line) if not."""
        if not isinstance(text, str) or not text.strip():
            raise ValueError("a file path is needed")
        if "\x00" in text:
            raise ValueError("a file path cannot hold a NUL character")
        named = text.strip()
        try:
            path = (self.root / named).resolve()
        except (OSError, RuntimeError) as error:  # RuntimeError: a loop of symbolic links (Python < 3.13)
            raise ValueError(f"{named}: cannot be resolved: {error}") from None
        if not any(path.is_relative_to(root) for root in self.roots):
            folders = ", ".join(map(str, self.roots))
            raise ValueError(f"{named}: outside the station's folders ({folders}); the page opens and saves only there "
                             "(links are followed before the check)")
        if path.suffix.lower() != ".xml":
            raise ValueError(f"{named}: an application file ends in .xml")
        return path

    def shown(self, path: Path) -> str:
        """A path as the page shows it: relative to the first folder when it is below it."""
        try:
            return str(path.relative_to(self.root))
        except ValueError:
            return str(path)
