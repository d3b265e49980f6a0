"""The README and the docs tell the truth: their commands run as written, the CLI table is
the parser's, their links lead somewhere, and the README stays a front door.

README.md and every docs/*.md page are parsed when the tests run, so sections, pages and
options added later are checked too. What is run, page by page:

- every ```bash block, line by line in one scratch folder (tmp_path), each command
  through the rule of :data:`RUNNERS` for its first word(s); a command no rule knows
  fails the test: add a rule (run it, run it reduced, or skip it with a reason). A
  comment line right after a command that starts with ``#   `` is output the command
  prints: it must appear in what the command printed;
- every plain ``` block that starts with ``$ ``: a transcript. Its ``$`` lines are run
  the same way and every other line it shows (but ``...``) must be printed by them.

- every ```python block: the README's all in one namespace in their order, in a scratch
  folder holding the ``poses.csv`` the examples read, made as the README says
  (``kincal simulate ec66 --out poses.csv``); then each docs page's blocks, in their order, in a copy
  of that namespace (the pages go on from the README's example: its ``robot``, ``data``
  and ``result``), in the same folder.

Paths ``../shared/`` (the project's shared data beside the repository) are pointed at
the real folder (``KINCAL_SHARED`` overrides it); a block that needs it is skipped when
it is not there. The option tables live on docs/cli.md.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import shlex
import warnings
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import REPO, SHARED

from kincal.cli.main import build_parser, main

README = REPO / "README.md"
DOCS = REPO / "docs"
CLI_PAGE = DOCS / "cli.md"  # the command and option tables
README_MAX_LINES = 300  # a front door: what it does, the two commands, an example, links
SHARED_DIR = Path(os.environ.get("KINCAL_SHARED", SHARED))


def pages() -> list[Path]:
    """The README, then the docs pages in name order."""
    return [README] + sorted(DOCS.glob("*.md"))


def _name(page: Path) -> str:
    return page.relative_to(REPO).as_posix()


# ------------------------------------------------------------------ the pages
@dataclass(frozen=True)
class Step:
    line: int  # line of the page
    command: str
    expected: tuple[str, ...]  # output lines the page shows for it


def _blocks(text: str):
    """(language, first line number, lines) of every fenced block of a page."""
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[k])
        if m:
            end = next(j for j in range(k + 1, len(lines)) if lines[j].startswith("```"))
            yield m.group(1), k + 2, lines[k + 1:end]
            k = end
        k += 1


def _steps(language: str, first: int, lines: list[str]) -> list[Step]:
    steps: list[Step] = []
    if language == "bash":
        joined: list[tuple[int, str]] = []  # lines continued with a backslash, joined
        for n, line in enumerate(lines, start=first):
            if joined and joined[-1][1].endswith("\\"):
                joined[-1] = (joined[-1][0], joined[-1][1][:-1].rstrip() + " " + line.strip())
            else:
                joined.append((n, line))
        for n, line in joined:
            if line.startswith("#   ") and steps:  # the output of the command above
                last = steps[-1]
                steps[-1] = Step(last.line, last.command, last.expected + (line[1:].strip(),))
            elif line.strip() and not line.lstrip().startswith("#"):
                steps += [Step(n, part.strip(), ()) for part in line.split("&&")]
    elif language == "" and lines and lines[0].startswith("$ "):  # a transcript
        shown = []
        for n, line in enumerate(lines, start=first):
            if line.startswith("$ "):
                steps.append(Step(n, line[2:].strip(), ()))
            elif line.strip() and not line.strip().endswith("..."):
                shown.append(line.strip())
        if steps:  # the output of the commands together
            steps[-1] = Step(steps[-1].line, steps[-1].command, tuple(shown))
    return steps


def examples() -> list[tuple[str, int, list[Step]]]:
    """(page, first line, steps) of every block that is run, README first."""
    out = []
    for page in pages():
        for language, first, lines in _blocks(page.read_text(encoding="utf-8")):
            steps = _steps(language, first, lines)
            if steps:
                out.append((_name(page), first, steps))
    return out


# ------------------------------------------------------------------ how to run
def _run_kincal(argv: list[str]) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse: usage errors
            code = exc.code
    return code, out.getvalue() + err.getvalue()


def _skip(reason):
    def run(argv):
        return None, reason

    return run


# The first word(s) of a command -> how the test runs it. kincal itself runs in-process
# through the entry point's main(); commands that cannot run inside a test are skipped
# here with the reason, so that skipping is a visible decision.
RUNNERS = {
    "kincal": lambda argv: _run_kincal(argv[1:]),
    # the same command (with --out) runs, and its numbers are checked, in
    # tests/test_cli.py::test_demo_writes_tables_and_plots_whose_numbers_hold (~10 s)
    "kincal demo": _skip("run by tests/test_cli.py::test_demo_writes_tables_and_plots_whose_"
                         "numbers_hold"),
    "pip install": _skip("installing is what made this test environment; CI's .ci/run "
                         "installs the package into a fresh environment the same way"),
    "python -m pytest": _skip("the test suite itself"),
    # a second or so: Kabsch fits of the TIAGo marker files into pose files
    "python scripts/tiago_pose_files.py": lambda argv: _run_script(argv[1:]),
}


def _run_script(argv: list[str]):
    """A repository script, in a fresh interpreter (it imports its neighbours)."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, str(REPO / argv[0]), *argv[1:]], capture_output=True,
                       text=True)
    return r.returncode, r.stdout + r.stderr


def _runner(argv: list[str]):
    for words in sorted(RUNNERS, key=len, reverse=True):
        if argv[:len(words.split())] == words.split():
            return RUNNERS[words]
    return None


def _normalise(text: str) -> str:
    return " ".join(text.split())


# Files a page simulates and then shows figures of: SHA-256 of their data rows (comments
# off) as the pages' figures were measured. simulate's poses come from iterative inverse
# kinematics whose arm branch can turn on the BLAS kernels' last bits (OpenBLAS's
# Sandybridge kernels draw other R-test poses than its Haswell and SkylakeX ones); on such
# a machine the commands still run, and the figures are not compared (a skip says why).
DRAWN = {"rt.csv": "942c8fc69e8ba7bee819898784db8b6a6847f34c7960898601a5903bde83a46a"}
MEASURED_ON = {"Haswell", "SkylakeX"}  # OpenBLAS kernels that draw them (seen 2026-11-24)


def _kernels() -> set:
    """The OpenBLAS kernels numpy and scipy run on here (empty: another BLAS)."""
    import scipy.linalg  # noqa: F401 (its own OpenBLAS, listed once loaded)
    from threadpoolctl import threadpool_info

    return {str(i.get("architecture")) for i in threadpool_info()
            if i.get("internal_api") == "openblas"}


def _other_draws(argv: list[str]) -> str:
    """"" or why the file a ``kincal simulate`` step wrote is not the one the page shows."""
    import hashlib

    if argv[:2] != ["kincal", "simulate"] or "--out" not in argv:
        return ""
    name = argv[argv.index("--out") + 1]
    if name not in DRAWN:
        return ""
    rows = "".join(line for line in Path(name).read_text().splitlines(keepends=True)
                   if not line.startswith("#"))
    kernels = _kernels()
    if hashlib.sha256(rows.encode()).hexdigest() == DRAWN[name] or (
            kernels and kernels <= MEASURED_ON):  # there a changed file is a changed page
        return ""
    return (f"{' '.join(argv)} drew other poses on this machine's BLAS kernels than the page "
            "shows figures of: the commands ran, their figures are not compared")


@pytest.mark.parametrize("page, first, steps", examples(),
                         ids=[f"{page}:line{first}" for page, first, _ in examples()])
def test_page_commands_run(page, first, steps, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    printed = ""
    skipped = []
    other = ""  # the page's simulated file is not the one its figures come from
    for step in steps:
        where = f"{page} line {step.line}"
        command = step.command
        if "../shared/" in command:
            if not SHARED_DIR.is_dir():
                pytest.skip(f"{where} needs ../shared, not present")
            command = command.replace("../shared/", f"{SHARED_DIR}/")
        argv = shlex.split(command)
        run = _runner(argv)
        assert run is not None, (f"{where}: no rule to run {step.command!r}; "
                                 "add one to RUNNERS in tests/test_readme.py")
        code, output = run(argv)
        if code is None:
            skipped.append(f"{where}: {output}")
            continue
        assert code == 0, f"{where}: {step.command!r} exited {code}:\n{output}"
        printed += output
        other = other or _other_draws(argv)
        lines = {_normalise(line) for line in printed.splitlines()}
        for shown in ([] if other else step.expected):
            assert _normalise(shown) in lines, (
                f"{where}: {step.command!r} did not print {shown!r}; it printed:\n{printed}")
    if skipped and len(skipped) == len(steps):
        pytest.skip("; ".join(skipped))
    if other and any(step.expected for step in steps):
        pytest.skip(other)


def test_every_page_command_has_a_rule():
    for page, _, steps in examples():
        for step in steps:
            argv = shlex.split(step.command)
            assert _runner(argv) is not None, (
                f"{page} line {step.line}: no rule to run {step.command!r}; add one to "
                "RUNNERS in tests/test_readme.py")


def test_the_parser_finds_the_blocks():
    # guards the parsing above: the blocks these pages are known to have are found
    by_page: dict[str, list[str]] = {}
    for page, _, steps in examples():
        by_page.setdefault(page, []).extend(s.command for s in steps)
    assert "kincal demo" in by_page["README.md"] and "pip install ." in by_page["README.md"]
    assert any(c.startswith("kincal plan ec66 --random") for c in by_page["docs/planning.md"])
    assert any(c.startswith("kincal compensate cal.urdf") for c in by_page["docs/cell.md"])
    assert any("tiago_mocap" in c for c in by_page["docs/results.md"])


# ------------------------------------------------------------------ the front door
def test_readme_is_a_front_door():
    text = README.read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines (at most {README_MAX_LINES}): move reference, "
        "method and results to a docs/ page and link it")
    # the quick start's two commands, as written; CI (.ci/run) runs the second one
    quick = next(b for language, _, b in _blocks(text) if language == "bash")
    assert quick == ["pip install . && kincal demo",
                     'pip install ".[test]" && python -m pytest -q']
    assert quick[1] in (REPO / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    for heading in ("## Quick start", "## Python API", "## Limitations", "## Documentation"):
        assert heading in lines, f"README.md has no section {heading!r}"
    linked = {target.split("#")[0] for target in _links(text)}
    unlinked = [_name(p) for p in sorted(DOCS.glob("*.md")) if _name(p) not in linked]
    assert not unlinked, f"docs pages the README does not link to: {unlinked}"


def _anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower().replace("`", "")
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _without_code(text: str) -> str:
    """The page's prose: fenced blocks and inline code spans blanked out."""
    kept, fenced = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
            continue
        kept.append("" if fenced else line)
    return re.sub(r"`[^`]+`", "", "\n".join(kept))  # a code span may go over a line end


def _anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    fenced = False
    for line in page.read_text(encoding="utf-8").splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(r"^#{1,6} ", line):
            base = _anchor(line.lstrip("#"))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def _links(text: str) -> list[str]:
    """Targets of the page's relative links (web addresses left out)."""
    targets = re.findall(r"\]\(([^()\s]+)\)", _without_code(text))
    return [t for t in targets if not re.match(r"^[a-z]+:", t)]


@pytest.mark.parametrize("page", pages(), ids=_name)
def test_links_lead_to_pages_and_anchors_that_exist(page):
    problems = []
    for target in _links(page.read_text(encoding="utf-8")):
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.is_file():
            problems.append(f"{target}: no file {file}")
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            problems.append(f"{target}: no heading with anchor #{anchor} in {file.name} "
                            f"(anchors: {', '.join(sorted(_anchors(file)))})")
    assert not problems, f"{_name(page)}:\n" + "\n".join(problems)


def test_anchor_rules():
    assert _anchor(" Choosing the penalty: cross-validation, evidence, or automatic") == (
        "choosing-the-penalty-cross-validation-evidence-or-automatic")
    assert _anchor(" Inside a measurement volume (plan --in-cube)") == (
        "inside-a-measurement-volume-plan---in-cube")
    assert _anchor(" Error models on an arm with 6-D placement errors") == (
        "error-models-on-an-arm-with-6-d-placement-errors")
    assert _links("see [a](docs/a.md#x), [web](https://x.org) and `[b](c.md)`") == [
        "docs/a.md#x"]


# ------------------------------------------------------------------ the CLI table
def _subparsers(parser) -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _options(parser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings
            if o.startswith("--") and o != "--help"}


def _cells(row: str) -> list[str]:
    return [c.strip() for c in re.split(r"(?<!\\)\|", row.strip())[1:-1]]


def documented_options(text: str, commands) -> tuple[dict[str, set[str]], list[str]]:
    """({command: options the command and option tables of a page document}, problems).

    A row of the command table whose first cell starts with ``kincal COMMAND`` documents
    the options in that cell for COMMAND; a row of the options table (header ``option |
    commands``) documents the options of its first cell for every command named in its
    second cell.
    """
    documented = {c: set() for c in commands}
    problems = []
    table_kind = None
    for line in text.splitlines():
        if not line.startswith("|"):
            table_kind = None
            continue
        cells = _cells(line)
        if table_kind is None:  # the header row
            table_kind = cells[0].lower()
            continue
        if set(cells[0]) <= set("-: "):
            continue
        options = set(re.findall(r"--[a-z][a-z0-9-]*", cells[0]))
        if table_kind == "command":
            m = re.match(r"`kincal (\w+)", cells[0])
            if not m or m.group(1) not in documented:
                problems.append(f"row {cells[0][:40]!r}: not a kincal command")
                continue
            documented[m.group(1)] |= options
        elif table_kind == "option":
            names = re.findall(r"[a-z]+", cells[1])
            unknown = [n for n in names if n not in documented]
            if unknown or not names:
                problems.append(f"option row {cells[0][:40]!r}: unknown command(s) {unknown}")
            for n in names:
                if n in documented:
                    documented[n] |= options
    return documented, problems


def test_cli_table_matches_the_parser():
    parser = build_parser()
    commands = _subparsers(parser)
    text = CLI_PAGE.read_text(encoding="utf-8")
    documented, problems = documented_options(text, commands)
    for name, sub in commands.items():
        if not documented[name] and f"`kincal {name}" not in text:
            problems.append(f"kincal {name} has no row in the command table")
        missing = sorted(_options(sub) - documented[name])
        if missing:
            problems.append(f"kincal {name}: options missing from the command or option "
                            f"table of docs/cli.md: {', '.join(missing)}")
        unknown = sorted(documented[name] - _options(sub))
        if unknown:
            problems.append(f"kincal {name}: docs/cli.md documents options the parser does "
                            f"not have: {', '.join(unknown)}")
    for option in sorted(_options(parser)):  # kincal --version
        if f"kincal {option}" not in text:
            problems.append(f"docs/cli.md does not mention `kincal {option}`")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("page", pages(), ids=_name)
def test_inline_commands_name_real_options(page):
    """Every `kincal COMMAND ... --option` span in a page's text uses options the parser
    has for that command (complete ones must parse)."""
    parser = build_parser()
    commands = _subparsers(parser)
    text = page.read_text(encoding="utf-8")
    problems = []
    for span in re.findall(r"`(kincal [^`\n]+)`", text):
        words = span.split()
        if len(words) < 2 or words[1].startswith("--") or words[1].isupper():
            continue  # `kincal --version`, `kincal COMMAND --help`
        if words[1] not in commands:
            problems.append(f"`{span}`: no command {words[1]!r}")
            continue
        unknown = set(re.findall(r"--[a-z][a-z0-9-]*", span)) - _options(commands[words[1]])
        if unknown:
            problems.append(f"`{span}`: {', '.join(sorted(unknown))} not options of "
                            f"kincal {words[1]}")
        placeholder = re.search(r"[A-Z]{2,}|\.\.\.|\[|\\\|", span)
        # a complete command (positionals after the command word): it must parse
        if not placeholder and len(words) > 2 and not words[2].startswith("--"):
            try:
                with contextlib.redirect_stderr(io.StringIO()):
                    parser.parse_args(shlex.split(span)[1:])
            except SystemExit:
                problems.append(f"`{span}` does not parse")
    assert not problems, f"{_name(page)}:\n" + "\n".join(problems)


def test_block_parsing_rules():
    bash = ["# a comment", "kincal simulate ec66 \\", "    --out a.csv", "#   simulated 60 poses",
            "", "pip install . && kincal demo"]
    assert _steps("bash", 10, bash) == [
        Step(11, "kincal simulate ec66 --out a.csv", ("simulated 60 poses",)),
        Step(15, "pip install .", ()), Step(15, "kincal demo", ())]
    transcript = ["$ kincal plan ec66", "$ kincal analyze ec66 a.csv", "shown line", "  ...",
                  "  more ..."]
    assert _steps("", 1, transcript) == [Step(1, "kincal plan ec66", ()),
                                         Step(2, "kincal analyze ec66 a.csv", ("shown line",))]
    assert _steps("", 1, ["output without a command"]) == []
    assert _steps("python", 1, ["$ kincal demo"]) == []


def _poses_csv(folder: Path) -> None:
    """The poses.csv of the README's API examples, made as the README tells a reader to
    make one: ``kincal simulate ec66 --out poses.csv`` (joint columns and x,y,z, rows in
    acquisition order, no time-stamp column), so the pages' examples run on the file a
    reader has, not on one made for the test."""
    here = Path.cwd()
    os.chdir(folder)
    try:
        code, output = _run_kincal(["simulate", "ec66", "--out", "poses.csv", "--quiet"])
    finally:
        os.chdir(here)
    assert code == 0, output


def _python_blocks(page: Path) -> list[tuple[int, list[str]]]:
    return [(first, lines) for language, first, lines in
            _blocks(page.read_text(encoding="utf-8")) if language == "python"]


def _exec_blocks(page: Path, namespace: dict) -> None:
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the examples' own warnings are not the point here
        for first, lines in _python_blocks(page):
            code = compile("\n".join(lines), f"{_name(page)}, block at line {first}", "exec")
            exec(code, namespace)  # noqa: S102 - the page's own example code


@pytest.fixture(scope="module")
def readme_namespace(tmp_path_factory):
    """(folder, namespace) after the README's Python examples ran in folder."""
    folder = tmp_path_factory.mktemp("examples")
    _poses_csv(folder)
    namespace: dict = {}
    here = Path.cwd()
    os.chdir(folder)
    try:
        _exec_blocks(README, namespace)
    finally:
        os.chdir(here)
    return folder, namespace


def test_readme_python_examples_run(readme_namespace):
    assert _python_blocks(README), "the README has no Python example"
    folder, namespace = readme_namespace
    assert (folder / "ec66_calibrated.urdf").exists()
    assert {"robot", "data", "result"} <= set(namespace)


DOCS_WITH_PYTHON = [p for p in pages()[1:] if _python_blocks(p)]


@pytest.mark.parametrize("page", DOCS_WITH_PYTHON, ids=_name)
def test_docs_python_examples_run(page, readme_namespace, monkeypatch):
    folder, namespace = readme_namespace
    monkeypatch.chdir(folder)
    _exec_blocks(page, dict(namespace))  # a copy: one page's names do not reach another
