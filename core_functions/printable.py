"""Text from a file, shown on a console or in a report without the characters that make it lie.

An operation id, a group name, a function name or an error text read from a trace, a recording or
an application is outside input.  A control character in it can move the cursor, clear the line or
recolour the terminal; a bidirectional formatting character (RIGHT-TO-LEFT OVERRIDE, U+202E, and
its kin) reverses what follows, so ``op1<RLO>gnp.exe`` reads as ``op1exe.png``, and two different
ids can look alike.  :func:`printable` shows every such character as its Python escape (``\\u202e``,
``\\x1b``), so what the operator reads is what the file holds; :func:`unsafe_character` finds the
first one, for a reader that refuses them outright (an application's ids).
"""
from __future__ import annotations

import unicodedata

#: Unicode categories that are never shown as they are: controls (C0, C1, DEL), format characters
#: (the bidi embeddings, overrides, isolates and marks, zero-width characters), line and paragraph
#: separators, surrogates, private use and unassigned code points.
UNSAFE_CATEGORIES = frozenset({"Cc", "Cf", "Zl", "Zp", "Cs", "Co", "Cn"})


def is_unsafe(character: str) -> bool:
    return unicodedata.category(character) in UNSAFE_CATEGORIES


def printable(text: object) -> str:
    """``text`` (any object: ``str()`` of it) with every unsafe character escaped; the rest as it is."""
    shown = str(text)
    if shown.isprintable() and shown.isascii():  # the usual case, at no cost
        return shown
    return "".join(_escape(c) if is_unsafe(c) else c for c in shown)


def unsafe_character(text: str) -> str | None:
    """The first unsafe character of ``text`` described (``RIGHT-TO-LEFT OVERRIDE (U+202E)``), or None."""
    for character in text:
        if is_unsafe(character):
            return f"{unicodedata.name(character, 'a control character')} (U+{ord(character):04X})"
    return None


def _escape(character: str) -> str:
    code = ord(character)
    if code < 0x100:
        return f"\\x{code:02x}"
    if code < 0x10000:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"
