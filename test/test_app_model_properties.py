"""Property tests: whatever the bytes, the loader answers with diagnostics, never with a crash."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
from app_model_support import APP_XML, CELL_XML, small_catalog
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lxml import etree

from execution_engine.app_model import ApplicationError, Diagnostic, load_application, load_cell, validate_application, validate_cell
from execution_engine.app_model.diagnostics import DiagnosticLog
from execution_engine.app_model.positions import DocumentWalk, SourceMap
from execution_engine.app_model.reader import ApplicationReader
from execution_engine.app_model.safe_xml import read_xml
from execution_engine.app_model.schema import load_schema
from execution_engine.app_model.structure import StructureCheck, validate_structure

CATALOG = small_catalog()
SETTINGS = settings(suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow], deadline=None)


def assert_well_formed(diagnostics: list[Diagnostic], data: bytes) -> None:
    lines = data.count(b"\n") + data.count(b"\r") + 1
    for d in diagnostics:
        assert 1 <= d.line <= lines and d.col >= 1 and d.message
    assert diagnostics == sorted(diagnostics, key=Diagnostic.sort_key)


@pytest.fixture
def work(tmp_path: Path) -> Path:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    return tmp_path


@SETTINGS
@given(data=st.binary(max_size=2000))
def test_random_bytes_give_diagnostics_not_exceptions(work: Path, data: bytes) -> None:
    path = work / "random.xml"
    path.write_bytes(data)
    found = validate_application(path, CATALOG)
    assert found  # random bytes are never a valid application
    assert_well_formed(found, data)
    with pytest.raises(ApplicationError):
        load_application(path, CATALOG)
    assert_well_formed(validate_cell(path), data)


def test_every_truncation_of_a_valid_application_is_reported(work: Path) -> None:
    data = APP_XML.encode()
    complete = data.index(b"</application>") + len(b"</application>")
    path = work / "cut.xml"
    for cut in range(len(data)):
        path.write_bytes(data[:cut])
        found = validate_application(path, CATALOG)
        if cut < complete:
            assert found, f"cut at {cut} gave no diagnostic"
            assert found[0].line >= 1
        else:
            assert found == []
        assert_well_formed(found, data[:cut])


def test_every_truncation_of_a_valid_cell_is_reported(tmp_path: Path) -> None:
    data = CELL_XML.encode()
    complete = data.index(b"</cell>") + len(b"</cell>")
    path = tmp_path / "cut.xml"
    for cut in range(0, len(data)):
        path.write_bytes(data[:cut])
        found = validate_cell(path)
        assert bool(found) == (cut < complete), cut
        assert_well_formed(found, data[:cut])


_PIECES = st.sampled_from([
    "<", ">", "/>", "</operation>", "<operation>", '"', "'", "=", "&", "&amp;", "<!--", "-->", "<![CDATA[", "]]>",
    '<param value="x"/>', "<left_arm>", "<function name=\"wait\"/>", " id=\"1\"", "\n", "é", "\x00", "<!DOCTYPE a>",
])


@SETTINGS
@given(
    start=st.integers(0, len(APP_XML)),
    length=st.integers(0, 40),
    insert=st.lists(st.one_of(_PIECES, st.text(max_size=5)), max_size=4),
)
def test_mutated_applications_never_crash(work: Path, start: int, length: int, insert: list[str]) -> None:
    text = APP_XML[:start] + "".join(insert) + APP_XML[start + length:]
    data = text.encode("utf-8", errors="surrogatepass")
    path = work / "mutant.xml"
    path.write_bytes(data)
    found = validate_application(path, CATALOG)
    assert_well_formed(found, data)
    if any(d.is_error for d in found):
        with pytest.raises(ApplicationError):
            load_application(path, CATALOG)
    else:
        load_application(path, CATALOG)


@SETTINGS
@given(
    start=st.integers(0, len(CELL_XML)),
    length=st.integers(0, 40),
    insert=st.lists(st.one_of(_PIECES, st.text(max_size=5)), max_size=4),
)
def test_mutated_cells_never_crash(tmp_path: Path, start: int, length: int, insert: list[str]) -> None:
    data = (CELL_XML[:start] + "".join(insert) + CELL_XML[start + length:]).encode("utf-8", errors="surrogatepass")
    path = tmp_path / "mutant.xml"
    path.write_bytes(data)
    found = validate_cell(path)
    assert_well_formed(found, data)
    if any(d.is_error for d in found):
        with pytest.raises(ApplicationError):
            load_cell(path)


# ------------------------------------------------------------------------------ positions
_NAMES = st.sampled_from(["a", "b", "op", "x.y", "param", "n-1"])
_VALUES = st.text(alphabet=st.sampled_from(list("ab >/=<'\"&\n\t é")), max_size=8)
_GAPS = st.sampled_from([" ", "\n", "\t", "  \n  "])


@st.composite
def documents(draw: st.DrawFn, depth: int = 0) -> str:
    """Random well-formed XML with multi-line tags, odd attribute values, comments and CDATA."""
    name = draw(_NAMES)
    attributes = draw(st.dictionaries(st.sampled_from(["id", "name", "value", "v2"]), _VALUES, max_size=3))
    rendered = "".join(
        f"{draw(_GAPS)}{key}{draw(st.sampled_from(['=', ' = ']))}" + (f'"{escape(v)}"' if draw(st.booleans()) else f"'{escape(v)}'")
        for key, v in attributes.items()
    )
    children = draw(st.lists(st.one_of(
        st.just("<!-- <fake a='1'> -->"), st.just("<![CDATA[ <fake/> ]]>"), st.just("<?pi <fake/> ?>"), st.just("text\n"),
        *( [documents(depth + 1)] if depth < 3 else [] ),
    ), max_size=4))
    close = draw(st.sampled_from([">", "\n>", " >"]))
    if not children and draw(st.booleans()):
        empty_end = draw(st.sampled_from(["/>", " />", "\n/>"]))
        return f"<{name}{rendered}{empty_end}"
    return f"<{name}{rendered}{close}{''.join(children)}</{name}>"


def escape(value: str) -> str:
    return value.replace("&", "&amp;").replace("<", "&lt;").replace('"', "&quot;").replace("'", "&apos;")


@SETTINGS
@given(body=documents(), prefix=st.sampled_from(["", "<?xml version='1.0'?>\n", "<!-- <x> -->\n", "\ufeff"]))
def test_every_element_and_attribute_is_located_exactly(body: str, prefix: str) -> None:
    text = prefix + body
    root = etree.fromstring(text.encode())
    source = SourceMap("f.xml", text.lstrip("\ufeff"), root)
    lines = text.lstrip("\ufeff").split("\n")
    for element in root.iter(etree.Element):
        where = source.element(element)
        line = lines[where.line - 1]
        assert line[where.col - 1:].startswith(f"<{element.tag}"), (element.tag, where)
        for attribute in map(str, element.attrib):
            spot = source.attribute(element, attribute)
            assert re.match(re.escape(attribute) + r"\s*=", lines[spot.line - 1][spot.col - 1:]), (attribute, spot)


# ------------------------------------------------------------------------------ the reader's walk
_JUNK = st.sampled_from([
    "<!-- c -->", "<?pi x?>", "<junk a='1'><function name='x'/></junk>", '<function name="extra"/>',
    '<params><param value="p"/></params>', "<left_arm><function name='wait'/></left_arm>", "<param value='q'/>",
    "<operation id='9'><arm><function name='wait'/></arm></operation>", "<![CDATA[<x/>]]>", "text",
])


@SETTINGS
@given(cuts=st.lists(st.tuples(st.integers(0, len(APP_XML)), _JUNK), max_size=4))
def test_the_reader_walk_gives_every_element_its_own_offset(work: Path, cuts: list[tuple[int, str]], monkeypatch: pytest.MonkeyPatch) -> None:
    """Junk anywhere (where it keeps the file well-formed) never shifts the offsets the reader hands out."""
    text = APP_XML
    for position, junk in sorted(cuts, reverse=True):
        tag_end = text.rfind(">", 0, position)
        if tag_end > 0 and text.startswith("<", text.find("<", tag_end)):  # insert between tags only
            text = text[:tag_end + 1] + junk + text[tag_end + 1:]
    try:
        etree.fromstring(text.encode())
    except etree.XMLSyntaxError:
        return  # junk inside the prolog or after the root: not what this test is about
    visits: list[tuple[etree._Element, int]] = []
    walks: list[DocumentWalk] = []
    original = DocumentWalk.visit

    def recording(self: DocumentWalk, element: etree._Element) -> int:
        offset = original(self, element)
        visits.append((element, offset))
        walks.append(self)
        return offset

    monkeypatch.setattr(DocumentWalk, "visit", recording)
    path = work / "junk.xml"
    path.write_text(text)
    validate_application(path, CATALOG)
    assert visits
    assert all(walk.aligned for walk in walks)  # the fast path held: no fallback to the element map
    truths: dict[str, dict[str, int]] = {}
    for (element, offset), walk in zip(visits, walks):  # the application's walk, and its cell's
        file = walk.source.file
        if file not in truths:
            doc, _ = read_xml(path if file == str(path) else work / "cells" / "rivet_cell.xml")
            assert doc is not None
            truths[file] = {doc.root.getroottree().getpath(e): o for e, o in doc.source._element_offsets().items()}
        assert offset == truths[file][element.getroottree().getpath(element)], element.tag
    assert str(path) in truths
    # the reader's hottest loop visits <function> and <param> inline: each offset it kept is the
    # start of an element of that name, none twice (truth: the map of every element)
    doc, _ = read_xml(path)
    assert doc is not None
    by_offset = {o: e.tag for e, o in doc.source._element_offsets().items()}
    reader = ApplicationReader(doc)
    draft = reader.read()
    assert reader.walk.aligned
    kept = [(op.at, "operation") for op in draft.operations]
    for op in draft.operations:
        kept += [(call.at, "function") for call in op.calls.values()]
        kept += [(at, "param") for call in op.calls.values() for at in call.param_at]
    assert all(by_offset.get(offset) == tag for offset, tag in kept), kept
    assert len({offset for offset, _ in kept}) == len(kept)


@SETTINGS
@given(cuts=st.lists(st.tuples(st.integers(0, len(APP_XML)), _JUNK), max_size=4), cell=st.booleans())
def test_the_parser_finds_a_file_valid_exactly_when_the_structure_check_finds_nothing(
    work: Path, cuts: list[tuple[int, str]], cell: bool,
) -> None:
    """A file the validating parser accepts skips the structure check: it must be a file that check
    has nothing to say about, and every file it refuses must get the check's words."""
    text = CELL_XML if cell else APP_XML
    for position, junk in sorted(cuts, reverse=True):
        tag_end = text.rfind(">", 0, min(position, len(text)))
        if tag_end > 0:
            text = text[:tag_end + 1] + junk + text[tag_end + 1:]
    path = work / "mutant.xml"
    path.write_text(text)
    name = "cell" if cell else "application"
    checked, _ = read_xml(path, schema=load_schema(name).schema)
    plain, _ = read_xml(path)
    assert (checked is None) == (plain is None)  # well-formed or not, whichever parser
    if plain is None or checked is None:
        return
    found = [str(d) for d in StructureCheck(plain, load_schema(name), DiagnosticLog()).run()]
    assert (checked.valid_against is not None) == (found == []), found
    assert [str(d) for d in validate_structure(checked, name)] == found
