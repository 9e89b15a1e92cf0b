"""Every command README.md and docs/*.md show works as written after README's two set-up commands.

The README installed into ``.venv`` and then told a newcomer to type ``python3 -m execution_engine
...`` -- the system's interpreter, which has none of it -- on a file ``my_app.xml`` that does not
exist.  This reads every shell command out of the documents' code blocks and checks, without
running anything:

* the interpreter is one the set-up provides: ``.venv/bin/python`` (or plain ``python`` in a
  document that activates an environment of its own first, as docs/ros2.md does; ``python3 -m
  venv`` makes one); the package's console scripts likewise need that activation;
* ``python -m execution_engine ...`` parses: the subcommand and every option, with the program's own
  parser, in-process;
* every file a command reads exists in the repository, is written by an earlier command of the same
  document (a trace, a recording, its checkpoint, a redirection), or is an obvious placeholder the
  prose defines (``APP.xml``, ``FILE``, ``/path/app.xml``);
* other modules of the project exist, scripts exist, and ``pip install '.[extra]'`` names extras
  setup.py defines.

Commands quoted inline in prose (``\\`python -m ...\\```) are held to the interpreter rule. The table
of docs/faults.md is exempt: it is the input of test/test_cli_faults.py, which runs every row with
the test's own interpreter, and the page says so.  A ``console`` block's ``$`` commands of the
program are also run and must print what the block shows.
"""
from __future__ import annotations

import argparse
import ast
import contextlib
import importlib.util
import io
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from operator_station.program import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL = ("sh", "bash", "shell", "console", "")
SETUP_PYTHONS = (".venv/bin/python", ".venv/bin/python3")
PROJECT = ("execution_engine", "robot_bridges", "operator_station", "core_functions", "app_functions")
SEPARATORS = {"&&", "||", ";", "|", "&", "(", ")"}
REDIRECTS = {">", ">>", "<", "2>", "&>"}


def console_scripts() -> set[str]:
    text = (ROOT / "setup.py").read_text(encoding="utf-8")
    return set(re.findall(r'"(\w+) = [\w.]+:\w+"', text))


def extras() -> set[str]:
    """The keys of setup.py's extras_require."""
    for node in ast.walk(ast.parse((ROOT / "setup.py").read_text(encoding="utf-8"))):
        if isinstance(node, ast.keyword) and node.arg == "extras_require" and isinstance(node.value, ast.Dict):
            return {k.value for k in node.value.keys if isinstance(k, ast.Constant)}
    raise AssertionError("setup.py has no extras_require")


@dataclass(frozen=True)
class Command:
    document: str
    line: int
    words: tuple[str, ...]
    text: str
    block: str  # the code block's language; "inline" for a span of prose
    output: tuple[str, ...] = ()  # what a console block shows it printing

    def __str__(self) -> str:
        return f"{self.document}:{self.line}: {self.text}"


@dataclass
class Context:
    """What the commands before this one in the same document have set up."""

    activated: bool = False
    written: set[str] = field(default_factory=set)


# ------------------------------------------------------------------------------ reading
def blocks(text: str) -> list[tuple[str, int, str]]:
    """(language, first line number, body) of every fenced block."""
    found = []
    for match in re.finditer(r"^```(\w*)[^\n]*\n(.*?)^```", text, re.M | re.S):
        found.append((match.group(1), text.count("\n", 0, match.start(2)) + 1, match.group(2)))
    return found


def split(line: str) -> list[list[str]]:
    """A shell line as simple commands (words), without comments and redirections."""
    lexer = shlex.shlex(line, posix=True, punctuation_chars=";&|<>()")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    commands: list[list[str]] = [[]]
    skip = False
    for token in lexer:
        if skip:
            skip = False
            commands[-1].append(">" + token)  # a file this command writes
            continue
        if token in SEPARATORS:
            commands.append([])
        elif token in REDIRECTS:
            skip = token != "<"
        else:
            commands[-1].append(token)
    return [c for c in commands if c]


def strip_prefix(words: list[str]) -> list[str]:
    """Without leading ``VAR=value`` assignments and ``time``."""
    index = 0
    while index < len(words) and (re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[index]) or words[index] == "time"):
        index += 1
    return words[index:]


def is_interpreter(word: str) -> bool:
    return word in ("python", "python3") or word.endswith(("/python", "/python3"))


def commands_of(document: Path) -> list[Command]:
    text = document.read_text(encoding="utf-8")
    name = document.relative_to(ROOT).as_posix()
    found: list[Command] = []
    for language, first, body in blocks(text):
        if language not in SHELL:
            continue
        lines = body.split("\n")
        index = 0
        while index < len(lines):
            number, line = first + index, lines[index]
            while line.endswith("\\") and index + 1 < len(lines):
                index += 1
                line = line[:-1] + " " + lines[index].strip()
            index += 1
            if language == "console":
                if not line.startswith("$ "):
                    continue
                line = line[2:]
                shown = []
                while index < len(lines) and not lines[index].startswith("$ ") and lines[index]:
                    shown.append(lines[index])
                    index += 1
            else:
                shown = []
            try:
                simple = split(line)
            except ValueError:
                simple = []
            for words in simple:
                core = strip_prefix(words)
                if not core:
                    continue
                if language == "" and not (is_interpreter(core[0]) or core[0] in console_scripts()):
                    continue  # an unlabelled block is a listing unless a line starts a program
                found.append(Command(name, number, tuple(words), line.strip(), language or "plain", tuple(shown)))
    return found


def inline_commands(document: Path) -> list[Command]:
    """Commands quoted in prose: spans that start with an interpreter."""
    text = document.read_text(encoding="utf-8")
    name = document.relative_to(ROOT).as_posix()
    for language, first, body in blocks(text):
        text = text.replace(f"```{language}\n{body}```", "\n" * (body.count("\n") + 1), 1) if body else text
    if document.name == "faults.md":  # the table is test_cli_faults.py's input, with its own interpreter
        text = "\n".join("" if line.startswith("|") else line for line in text.split("\n"))
    found = []
    for match in re.finditer(r"`([^`]+)`", text):
        span = " ".join(match.group(1).split())
        words = span.split()
        core = strip_prefix(words)
        if core and is_interpreter(core[0]) and len(core) > 1:
            found.append(Command(name, text.count("\n", 0, match.start()) + 1, tuple(words), span, "inline"))
    return found


COMMANDS = [c for d in DOCUMENTS for c in commands_of(d)]
INLINE = [c for d in DOCUMENTS for c in inline_commands(d)]


# ----------------------------------------------------------------------------- checking
def parse_program(words: list[str]) -> argparse.Namespace:
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            return build_parser().parse_args(words)
    except SystemExit:
        raise AssertionError(f"does not parse: {err.getvalue().strip() or out.getvalue().strip()}") from None


def placeholder(path: str) -> bool:
    """A name the prose defines for the reader's own file: APP.xml, FILE, /path/app.xml, <file>."""
    stem = Path(path).name.split(".")[0]
    return path.startswith("/path/") or "<" in path or (stem.isupper() and len(stem) > 1)


def reads(args: argparse.Namespace) -> list[str]:
    """The files a parsed ``python -m execution_engine`` command reads."""
    paths: list[str] = []
    for name in ("file", "image", "replay", "resume"):
        value = getattr(args, name, None)
        if isinstance(value, str):
            paths.append(value)
    paths += list(getattr(args, "files", None) or [])
    paths += [v for k, v in (getattr(args, "backend_option", None) or []) if k in ("config", "feedback") and k == "config"]
    return paths


def writes(args: argparse.Namespace) -> list[str]:
    """The files it writes: its outputs, and the checkpoint named after a recording or trace."""
    paths = [v for v in (getattr(args, n, None) for n in ("trace", "record", "checkpoint", "out")) if isinstance(v, str)]
    for value in (getattr(args, "record", None), getattr(args, "trace", None)):
        if isinstance(value, str):
            path = Path(value)
            paths.append(str(path.parent / (path.name.split(".")[0] + ".checkpoint.sqlite")))
    return paths


def check(command: Command, context: Context) -> list[str]:
    """What is wrong with one command, given what came before it in its document."""
    words = strip_prefix(list(command.words))
    problems: list[str] = []
    program, rest = words[0], words[1:]
    targets = [w[1:] for w in rest if w.startswith(">")]
    rest = [w for w in rest if not w.startswith(">")]
    context.written.update(targets)
    if program in (".", "source") and rest and rest[0].endswith("/bin/activate"):
        context.activated = True
        return problems
    if program in console_scripts() and not context.activated:
        return [f"{program} is on the PATH only in an activated environment: write .venv/bin/{program}"]
    if not is_interpreter(program):
        return problems
    creating_venv = program in ("python", "python3") and rest[:2] == ["-m", "venv"]
    if program not in SETUP_PYTHONS and not creating_venv and not context.activated:
        problems.append(f"{program}: not the interpreter the set-up installs into; write .venv/bin/python")
    if command.block == "inline":
        return problems
    if rest[:1] == ["-m"] and len(rest) > 1:
        module, arguments = rest[1], rest[2:]
        if module == "execution_engine":
            try:
                args = parse_program(arguments)
            except AssertionError as error:
                return [*problems, str(error)]
            for path in reads(args):
                if not ((ROOT / path).exists() or path in context.written or placeholder(path)):
                    problems.append(f"{path}: no such file in the repository, and no earlier command writes it")
            context.written.update(writes(args))
        elif module.split(".")[0] in PROJECT:
            if importlib.util.find_spec(module) is None:
                problems.append(f"no module {module}")
        elif module == "pip" and arguments[:1] == ["install"]:
            for spec in arguments[1:]:
                wanted = re.fullmatch(r"\.\[([\w,]+)\]", spec)
                if wanted and not set(wanted.group(1).split(",")) <= extras():
                    problems.append(f"{spec}: setup.py has no such extra (extras: {', '.join(sorted(extras()))})")
    elif rest and rest[0].endswith(".py") and not (ROOT / rest[0]).is_file():
        problems.append(f"{rest[0]}: no such script")
    return problems


def documents_checked() -> dict[str, list[str]]:
    """Every problem of every command, in document order (a document's commands build on each other)."""
    problems: dict[str, list[str]] = {}
    for document in DOCUMENTS:
        name = document.relative_to(ROOT).as_posix()
        context = Context()
        for command in sorted([c for c in COMMANDS + INLINE if c.document == name], key=lambda c: c.line):
            found = check(command, context)
            if found:
                problems[str(command)] = found
    return problems


# -------------------------------------------------------------------------------- tests
def test_the_documents_show_commands_and_the_reader_finds_them() -> None:
    """The extraction itself: README's set-up and 'Using it', the guide's walk-through, the studio's start."""
    readme = [c for c in COMMANDS if c.document == "README.md"]
    assert len(readme) >= 12
    assert any(c.words[:3] == ("python3", "-m", "venv") for c in readme)
    assert any("validate" in c.words for c in COMMANDS if c.document == "docs/application_xml.md")
    assert any("studio" in c.words for c in COMMANDS if c.document == "docs/studio.md")
    assert len(INLINE) >= 20


def test_every_documented_command_works_after_the_set_up() -> None:
    problems = documents_checked()
    assert not problems, "\n".join(f"{where}\n    " + "\n    ".join(found) for where, found in problems.items())


@pytest.mark.parametrize("words, problem", [
    (("python3", "-m", "execution_engine", "functions"), "not the interpreter the set-up installs into"),
    ((".venv/bin/python", "-m", "execution_engine", "validate", "my_app.xml"), "my_app.xml: no such file"),
    ((".venv/bin/python", "-m", "execution_engine", "run", "apps_xml/example.xml", "--sped", "10"), "does not parse"),
    ((".venv/bin/python", "-m", "pip", "install", ".[gui]"), "setup.py has no such extra"),
    ((".venv/bin/python", "-m", "execution_engine", "report", "run.mcap"), "run.mcap: no such file"),
    (("nextage_sim_bridge", "--transport", "dds"), "only in an activated environment"),
    ((".venv/bin/python", "bench/no_such_bench.py"), "no such script"),
])
def test_the_check_catches_what_a_newcomer_would_meet(words: tuple[str, ...], problem: str) -> None:
    found = check(Command("README.md", 1, words, " ".join(words), "sh"), Context())
    assert any(problem in p for p in found), found


def test_a_file_written_by_an_earlier_command_may_be_read_by_a_later_one() -> None:
    context = Context()
    record = Command("x.md", 1, (".venv/bin/python", "-m", "execution_engine", "run", "apps_xml/example.xml", "--record", "run.mcap"), "", "sh")
    assert check(record, context) == []
    for later in (("report", "run.mcap"), ("run", "apps_xml/example.xml", "--resume", "run.checkpoint.sqlite")):
        assert check(Command("x.md", 2, (".venv/bin/python", "-m", "execution_engine", *later), "", "sh"), context) == []


@pytest.mark.parametrize("command", [c for c in COMMANDS if c.output and "vision" in c.words], ids=str)
def test_a_console_block_shows_what_the_command_prints(command: Command, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    words = strip_prefix(list(command.words))
    assert words[:3] == [".venv/bin/python", "-m", "execution_engine"]
    out, err = io.StringIO(), io.StringIO()
    assert main(words[3:], out, err) == 0, err.getvalue()
    assert out.getvalue().splitlines() == list(command.output)
