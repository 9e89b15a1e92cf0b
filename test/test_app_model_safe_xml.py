"""Hostile and broken files: refused cleanly, at the right place, without expanding or fetching anything."""
from __future__ import annotations

import socket
from collections.abc import Iterator
from pathlib import Path

import pytest
from lxml import etree

from app_model_support import APP_XML, CELL_XML, small_catalog

from execution_engine.app_model import ApplicationError, load_application, load_cell, validate_application
from execution_engine.app_model.safe_xml import DEFAULT_MAX_BYTES, hardened_parser, read_xml

CATALOG = small_catalog()

BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE application [
  <!ENTITY lol "lol">
  <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">
  <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">
  <!ENTITY lol3 "&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;&lol2;">
  <!ENTITY lol4 "&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;&lol3;">
  <!ENTITY lol5 "&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;&lol4;">
  <!ENTITY lol6 "&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;&lol5;">
  <!ENTITY lol7 "&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;&lol6;">
  <!ENTITY lol8 "&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;&lol7;">
  <!ENTITY lol9 "&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;&lol8;">
]>
<application name="&lol9;" robot="nextage"><operation id="1"><left_arm><function name="wait"/></left_arm></operation></application>
"""

REFUSED = "<!DOCTYPE> declarations are not allowed (DTDs and entities are refused so a file cannot expand or fetch anything)"


@pytest.fixture
def listener() -> Iterator[socket.socket]:
    """A local TCP port that records whether anyone connected (nothing may)."""
    server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.setblocking(False)
    yield server
    server.close()


def assert_nobody_connected(server: socket.socket) -> None:
    with pytest.raises(BlockingIOError):
        server.accept()


def test_billion_laughs_is_refused_without_expansion(tmp_path: Path) -> None:
    path = tmp_path / "lol.xml"
    path.write_text(BILLION_LAUGHS)
    assert [str(d) for d in validate_application(path, CATALOG)] == [f"{path}:2:1: {REFUSED}"]
    with pytest.raises(ApplicationError):
        load_cell(path)


def test_external_entities_and_dtds_are_refused_without_network(tmp_path: Path, listener: socket.socket) -> None:
    port = listener.getsockname()[1]
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP SECRET")
    for doctype in (
        f'<!DOCTYPE application [<!ENTITY xxe SYSTEM "file://{secret}">]>',
        f'<!DOCTYPE application [<!ENTITY xxe SYSTEM "http://127.0.0.1:{port}/x">]>',
        f'<!DOCTYPE application SYSTEM "http://127.0.0.1:{port}/application.dtd">',
        f'<!DOCTYPE application [<!ENTITY % remote SYSTEM "http://127.0.0.1:{port}/p.dtd"> %remote;]>',
    ):
        path = tmp_path / "xxe.xml"
        path.write_text(f'<?xml version="1.0"?>\n{doctype}\n<application name="&xxe;" robot="nextage"/>\n')
        found = validate_application(path, CATALOG)
        assert [str(d) for d in found] == [f"{path}:2:1: {REFUSED}"]
        assert "TOP SECRET" not in "".join(d.message for d in found)
    assert_nobody_connected(listener)


def test_the_parser_itself_resolves_nothing(tmp_path: Path, listener: socket.socket) -> None:
    """Defence in depth: even if a DOCTYPE got past the refusal, lxml is set to expand and fetch nothing."""
    port = listener.getsockname()[1]
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP SECRET")
    text = (f'<!DOCTYPE a [<!ENTITY xxe SYSTEM "file://{secret}"><!ENTITY net SYSTEM "http://127.0.0.1:{port}/x">]>'
            "<a>&xxe;&net;</a>")
    root = etree.fromstring(text.encode(), hardened_parser())
    assert "TOP SECRET" not in etree.tostring(root).decode()
    assert_nobody_connected(listener)


def test_a_comment_may_mention_doctype(tmp_path: Path) -> None:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    path = tmp_path / "app.xml"
    path.write_text(APP_XML.replace("<application ", "<!-- no <!DOCTYPE or <!ENTITY here -->\n<application ", 1))
    assert validate_application(path, CATALOG) == []


def test_oversized_file_is_refused_before_parsing(tmp_path: Path) -> None:
    path = tmp_path / "big.xml"
    path.write_text(APP_XML)
    size = path.stat().st_size
    assert [str(d) for d in validate_application(path, CATALOG, max_bytes=size - 1)] == [
        f"{path}:1:1: the file is {size} bytes, over the limit of {size - 1} bytes"
    ]
    assert DEFAULT_MAX_BYTES == 32 * 1024 * 1024


def test_only_regular_local_files_are_read(tmp_path: Path) -> None:
    assert [str(d) for d in validate_application(tmp_path, CATALOG)] == [f"{tmp_path}:1:1: not a regular file"]
    assert [str(d) for d in validate_application("/dev/zero", CATALOG)] == ["/dev/zero:1:1: not a regular file"]
    missing = tmp_path / "missing.xml"
    assert [str(d) for d in validate_application(missing, CATALOG)] == [f"{missing}:1:1: cannot read the file: No such file or directory"]


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"\xff\xfe<\x00a\x00/\x00>\x00", "1:1: the file is UTF-16/32; only UTF-8 files are supported"),
        (b'<application name="t" robot="nextage">\n  <x a="\xe9"/>\n</application>', "2:9: invalid UTF-8 byte 0xe9 (files must be UTF-8)"),
        (b'<?xml version="1.0" encoding="ISO-8859-1"?>\n<a/>', "1:31: encoding 'ISO-8859-1' is not supported; write the file in UTF-8"),
        (b"", "1:1: the file is empty"),
        (b"just text", "1:1: no XML element found"),
        (b"<application>\n  <operation></opration>\n</application>", "2:25: closing tag </opration> does not match <operation> opened on line 2"),
        (b"<application>\n  <operation id=1/>\n</application>", "2:17: attribute value must be in quotes"),
        (b'<application name="t">\n  <operation id="1">', "2:21: the file ends before <operation> (line 2) is closed"),
        (b"<application>\n  &nbsp;\n</application>", "2:9: unknown entity &nbsp; (only &lt; &gt; &amp; &quot; &apos; and &#...; exist)"),
        (b'<application a="1" a="2"/>', "1:25: attribute a is given twice"),
        (b"<a/>\n<b/>", "2:1: text after the end of the root element"),
    ],
)
def test_unreadable_and_malformed_files(tmp_path: Path, content: bytes, expected: str) -> None:
    path = tmp_path / "f.xml"
    path.write_bytes(content)
    assert [str(d) for d in validate_application(path, CATALOG)] == [f"{path}:{expected}"]


def test_crlf_files_get_the_same_positions(tmp_path: Path) -> None:
    (tmp_path / "cells").mkdir()
    (tmp_path / "cells" / "rivet_cell.xml").write_text(CELL_XML)
    text = APP_XML.replace('name="debur_drilling"', 'name="debur_driling"')
    unix = tmp_path / "unix.xml"
    unix.write_text(text)
    dos = tmp_path / "dos.xml"
    dos.write_bytes(text.replace("\n", "\r\n").encode())
    strip = len(str(tmp_path)) + 1
    assert [str(d)[strip + 4:] for d in validate_application(unix, CATALOG)] == [
        str(d)[strip + 3:] for d in validate_application(dos, CATALOG)
    ] == [".xml:7:17: unknown function 'debur_driling' (did you mean 'debur_drilling'?)"]


def test_read_xml_returns_the_document_and_no_diagnostics_for_a_good_file(tmp_path: Path) -> None:
    path = tmp_path / "cell.xml"
    path.write_text(CELL_XML)
    doc, diagnostics = read_xml(path)
    assert diagnostics == [] and doc is not None and doc.root.tag == "cell" and doc.file == str(path)
    assert load_cell(path).name == "rivet_cell"
    with pytest.raises(ApplicationError):
        load_application(path, CATALOG)
