"""Teach a frame: the group's TCP where it stands, written into the cell model as a new or updated ``<frame>``.

An integrator jogs the hand onto a hole or a fixture's corner and wants that pose in the cell file, in the
file's own units, under the frame it belongs to -- without retyping numbers and without the rest of the file
changing.  So the edit is made on the file's text, not on a re-serialised tree: an updated frame gets its
``xyz`` and ``rpy`` replaced in place, a new one is one line added (inside its parent, or after the last
top-level frame), and everything else -- comments, quotes, indentation, other frames -- keeps its bytes.
The page is shown that change as a diff and saves it only when confirmed (:func:`save_taught`): the very
text that was shown, and only if the cell on disk is still the one the diff was made from.

Before anything is written the new cell is read by the project's own reader and the application using it
is validated against it (``read_application`` with its ``cell=`` pointed at the new text): a taught frame
that breaks either is refused with their messages, and nothing changes.
"""
from __future__ import annotations

import difflib
import hashlib
import math
import os
import re
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lxml import etree

from cell_runner.output_files import FilePlan, Output, Refused
from core_functions.catalog import Catalog
from core_functions.geometry import Pose
from execution_engine.app_model import Diagnostic, read_application
from execution_engine.app_model.cell import WORLD, Cell, read_cell
from execution_engine.app_model.safe_xml import hardened_parser

#: A frame's name, as the cell schema's ``identifier`` has it.
NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*")
#: One start tag of a frame, quotes respected (a ``>`` inside a value does not end it).
_FRAME_TAG = re.compile(r"<frame\b(?:[^>\"']|\"[^\"]*\"|'[^']*')*>")
_ATTRIBUTE = r"\b{name}\s*=\s*(\"[^\"]*\"|'[^']*')"
_LENGTH = {"m": 1.0, "mm": 1e-3}
_ANGLE = {"rad": 1.0, "deg": math.pi / 180.0}
#: Digits written per unit: a micrometre and a microradian, whatever the file's unit.
_DECIMALS = {"m": 6, "mm": 3, "rad": 6, "deg": 4}


class TeachRefused(ValueError):
    """A teach that cannot be made or saved; the message is the one line the page shows."""


@dataclass(frozen=True)
class TeachPlan:
    """One taught frame, ready to be confirmed: the cell's new text and what changed."""

    cell_path: Path
    shown: str  # the cell as the page names it
    digest: str  # SHA-256 of the bytes the edit was made on: a save needs the file unchanged
    text: str  # the whole new cell
    frame: str
    parent: str
    local: Pose  # the frame in its parent, SI units
    created: bool
    diff: tuple[str, ...]  # unified diff of the cell, old -> new
    moved: tuple[str, ...]  # frames below an updated one: they move with it

    def to_json(self) -> dict[str, Any]:
        return {"cell": self.shown, "digest": self.digest, "frame": self.frame, "parent": self.parent, "created": self.created,
                "xyz": list(self.local.position), "rpy": list(self.local.rpy()), "diff": list(self.diff), "moved": list(self.moved)}


def digest_of(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def plan_teach(cell_path: Path, shown: str, data: bytes, cell: Cell, name: str, parent: str, tcp: Pose) -> TeachPlan:
    """The cell ``data`` (read from ``cell_path``; ``cell`` is it read) with frame ``name`` at ``tcp`` (world)
    under ``parent``.  TeachRefused, one line, when the name or parent cannot be, or the file cannot be edited."""
    if not isinstance(name, str) or NAME.fullmatch(name) is None:
        raise TeachRefused(f"teach: the frame's name must be a name (a letter or _, then letters, digits, _ . -), got {name!r}")
    if parent != WORLD and parent not in cell.frames:
        raise TeachRefused(f"teach: parent {parent!r} is not a frame of {shown} (nor world)")
    taken = next((what for what, names in (("an element", cell.elements), ("a zone", cell.zones), ("a joint pose", cell.joint_poses)) if name in names), None)
    if taken is not None:
        raise TeachRefused(f"teach: {name!r} is {taken} of {shown}; a frame needs a name of its own")
    existing = cell.frames.get(name)
    if existing is not None and existing.parent != parent:
        raise TeachRefused(f"teach: frame {name!r} of {shown} is under {existing.parent!r}, not {parent!r}: teach it there, or give a new name")
    try:
        text = data.decode("utf-8")
        root = etree.fromstring(data, hardened_parser())
    except (UnicodeDecodeError, etree.LxmlError, ValueError) as error:
        raise TeachRefused(f"teach: {shown} cannot be read: {error}") from None
    length_unit = root.get("length_unit", "m") if root.get("length_unit") in _LENGTH else "m"
    angle_unit = root.get("angle_unit", "rad") if root.get("angle_unit") in _ANGLE else "rad"
    local = cell.pose(parent).inverse().compose(tcp)
    xyz = " ".join(_number(v / _LENGTH[length_unit], _DECIMALS[length_unit]) for v in local.position)
    rpy = " ".join(_number(v / _ANGLE[angle_unit], _DECIMALS[angle_unit]) for v in local.rpy())
    frames = {e.get("name"): e for e in root.iter("frame")}
    if existing is not None:
        new_text = _update(text, frames[name], name, xyz, rpy, shown)
        moved = tuple(f for f in cell.frames if f != name and _below(cell, f, name))
    else:
        new_text = _insert(text, root, frames.get(parent), name, parent, xyz, rpy, shown)
        moved = ()
    diff = tuple(line.rstrip("\n") for line in difflib.unified_diff(
        text.splitlines(keepends=True), new_text.splitlines(keepends=True), f"{shown} (on disk)", f"{shown} (taught)", n=1))
    return TeachPlan(cell_path, shown, digest_of(data), new_text, name, parent, local, existing is None, diff, moved)


def check_taught(plan: TeachPlan, app_path: Path, app_text: str, catalog: Catalog) -> list[str]:
    """Every error of the taught cell and of the application at ``app_path`` (its text ``app_text``) read
    with it, as one line each naming the real cell; empty when both validate."""
    with tempfile.TemporaryDirectory(prefix="studio_teach_") as folder:
        trial = Path(folder) / plan.cell_path.name
        trial.write_text(plan.text, encoding="utf-8")
        cell, problems = read_cell(trial, display=plan.shown)
        errors = [str(d) for d in problems if d.severity == "error"]
        if cell is None or errors:
            return errors or [f"{plan.shown}: the taught cell does not read back"]
        pointed, count = _CELL_ATTRIBUTE.subn(lambda m: f'{m.group(1)}"{_xml_attr(str(trial))}"', app_text, count=1)
        if not count:
            return [f"{app_path}: the application names no cell= to teach into"]
        app, diagnostics = read_application(app_path, catalog, data=pointed.encode("utf-8"))
        lines = [_named(d, str(trial), plan.shown) for d in diagnostics if d.severity == "error"]
        if app is None and not lines:
            lines = [f"{app_path}: the application does not validate with the taught cell"]
        return lines


def save_taught(plan: TeachPlan, app_path: Path, app_text: str, catalog: Catalog, outputs: Sequence[Output] = ()) -> None:
    """Write the taught cell over the file it came from, atomically (a temporary file beside it, then a rename),
    once it and the application validate, and only if the file is still the one the diff was made from.
    TeachRefused (one line, nothing written) otherwise; OSError when the folder cannot be written."""
    plan_files = FilePlan("teach").read("the application", app_path)
    for output in (*outputs, Output("teach", str(plan.cell_path), "the taught cell", "cell.xml")):
        plan_files.write(output)
    try:
        plan_files.check_clashes()
    except Refused as refusal:
        raise TeachRefused(f"teach: {refusal}") from None
    problems = check_taught(plan, app_path, app_text, catalog)
    if problems:
        raise TeachRefused(f"teach: not saved, the taught cell would not validate: {problems[0]}"
                           + (f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""))
    temporary = plan.cell_path.with_name(f".{plan.cell_path.name}.teach-{os.getpid()}")
    temporary.write_text(plan.text, encoding="utf-8")
    try:
        if digest_of(plan.cell_path.read_bytes()) != plan.digest:  # read last, right before the rename
            raise TeachRefused(f"teach: not saved, {plan.shown} changed since the diff was made: teach it again to see the change on the new file")
        os.replace(temporary, plan.cell_path)
    finally:
        if temporary.exists():
            temporary.unlink()


# ------------------------------------------------------------------------ the text edits
_CELL_ATTRIBUTE = re.compile(r"(<application\b(?:[^>\"']|\"[^\"]*\"|'[^']*')*?\bcell\s*=\s*)(\"[^\"]*\"|'[^']*')")


def _update(text: str, element: etree._Element, name: str, xyz: str, rpy: str, shown: str) -> str:
    """``text`` with the frame's ``xyz`` and ``rpy`` values replaced (or added after its name) in its start tag."""
    start, end = _start_tag(text, element, name, shown)
    tag = text[start:end]
    for attribute, value in (("xyz", xyz), ("rpy", rpy)):
        found = re.search(_ATTRIBUTE.format(name=attribute), tag)
        if found is not None:
            tag = f'{tag[:found.start(1)]}"{value}"{tag[found.end(1):]}'
        else:
            named = re.search(_ATTRIBUTE.format(name="name"), tag)
            assert named is not None  # _start_tag found the tag by it
            tag = f'{tag[:named.end()]} {attribute}="{value}"{tag[named.end():]}'
    return text[:start] + tag + text[end:]


def _insert(text: str, root: etree._Element, parent_element: etree._Element | None, name: str, parent: str, xyz: str, rpy: str, shown: str) -> str:
    """``text`` with a new frame: the last child of a frame ``parent`` (nested: no parent attribute), or for
    the world one line after the last top-level frame (with ``parent="world"``)."""
    if parent_element is not None:
        start, end = _start_tag(text, parent_element, parent, shown)
        indent = _indent(text, start)
        line = f'<frame name="{name}" xyz="{xyz}" rpy="{rpy}"/>'
        tag = text[start:end]
        if tag.endswith("/>"):  # <frame .../> becomes <frame ...> the new child </frame>
            opened = tag[:-2].rstrip() + ">"
            return f"{text[:start]}{opened}\n{indent}  {line}\n{indent}</frame>{text[end:]}"
        return _before_close(text, _closing_tag(text, end, parent_element), indent, line)
    line = f'<frame name="{name}" parent="world" xyz="{xyz}" rpy="{rpy}"/>'
    tops = [e for e in root if isinstance(e.tag, str) and e.tag == "frame"]
    if tops:  # one line after the last top-level frame
        last = tops[-1]
        start, end = _start_tag(text, last, str(last.get("name")), shown)
        if not text[start:end].endswith("/>"):
            end = text.index(">", _closing_tag(text, end, last)) + 1
        return f"{text[:end]}\n{_indent(text, start)}{line}{text[end:]}"
    first = next(iter(root), None)
    at = _line_start(text, first.sourceline) if first is not None and first.sourceline else _root_close(text, shown)
    return f"{text[:at]}  {line}\n{text[at:]}"


def _before_close(text: str, close: int, indent: str, line: str) -> str:
    """A child line just before the parent's ``</frame>`` at ``close``, one level deeper than the parent."""
    begin = text.rfind("\n", 0, close) + 1
    if text[begin:close].strip():  # the closing tag shares its line with something: break the line
        return f"{text[:close]}\n{indent}  {line}\n{indent}{text[close:]}"
    return f"{text[:begin]}{indent}  {line}\n{text[begin:]}"


def _closing_tag(text: str, after: int, element: etree._Element) -> int:
    """Where the ``</frame>`` of ``element`` starts: counted over the frames opened and closed after its start tag."""
    depth = 1
    for match in re.finditer(r"<!--.*?-->|<frame\b(?:[^>\"']|\"[^\"]*\"|'[^']*')*>|</frame\s*>", text[after:], re.S):
        token = match.group(0)
        if token.startswith("<!--"):
            continue
        if token.startswith("</"):
            depth -= 1
            if depth == 0:
                return after + match.start()
        elif not token.endswith("/>"):
            depth += 1
    raise TeachRefused(f"teach: the end of frame {element.get('name')!r} was not found")


def _start_tag(text: str, element: etree._Element, name: str, shown: str) -> tuple[int, int]:
    """The span of ``element``'s start tag in ``text``: the first frame tag named ``name`` from its line on."""
    line = element.sourceline or 1
    for match in _FRAME_TAG.finditer(text, _line_start(text, line)):
        named = re.search(_ATTRIBUTE.format(name="name"), match.group(0))
        if named is not None and named.group(1)[1:-1] == name:
            return match.start(), match.end()
    raise TeachRefused(f"teach: frame {name!r} was not found in the text of {shown}")


def _line_start(text: str, line: int) -> int:
    at = 0
    for _ in range(line - 1):
        at = text.index("\n", at) + 1
    return at


def _root_close(text: str, shown: str) -> int:
    close = text.rfind("</cell")
    if close < 0:
        raise TeachRefused(f"teach: {shown} has no </cell> to add the frame before")
    begin = text.rfind("\n", 0, close) + 1
    return begin if not text[begin:close].strip() else close


def _indent(text: str, at: int) -> str:
    begin = text.rfind("\n", 0, at) + 1
    head = text[begin:at]
    return head if not head.strip() else re.match(r"\s*", head).group(0)  # type: ignore[union-attr]


def _below(cell: Cell, frame: str, ancestor: str) -> bool:
    parent = cell.frames[frame].parent
    while parent != WORLD:
        if parent == ancestor:
            return True
        parent = cell.frames[parent].parent
    return False


def _number(value: float, decimals: int) -> str:
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "", "-") else text


def _xml_attr(text: str) -> str:
    return text.replace("&", "&amp;").replace('"', "&quot;").replace("<", "&lt;")


def _named(diagnostic: Diagnostic, trial: str, shown: str) -> str:
    return str(diagnostic).replace(trial, shown)
