"""The README tells the truth: its commands run as written, its CLI table is the parser's.

README.md is parsed when the tests run, so sections and options added later are checked
too. What is run:

- every ```bash block, line by line in one scratch folder (tmp_path), each command
  through the rule of :data:`RUNNERS` for its first word(s); a command no rule knows
  fails the test: add a rule (run it, run it reduced, or skip it with a reason). A
  comment line right after a command that starts with ``#   `` is output the command
  prints: it must appear in what the command printed;
- every plain ``` block that starts with ``$ ``: a transcript. Its ``$`` lines are run
  the same way and every other line it shows (but ``...``) must be printed by them.

- every ```python block, all in one namespace in the order of the README (later blocks
  use the ``robot`` and ``data`` of earlier ones), in a scratch folder holding the
  ``poses.csv`` the examples read: a simulated EC66 with an acquisition-time column ``t``.

Paths ``../shared/`` (the project's shared data beside the repository) are pointed at
the real folder (``KINCAL_SHARED`` overrides it); a block that needs it is skipped when
it is not there.
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
SHARED_DIR = Path(os.environ.get("KINCAL_SHARED", SHARED))


# ------------------------------------------------------------------ the README
@dataclass(frozen=True)
class Step:
    line: int  # line of README.md
    command: str
    expected: tuple[str, ...]  # output lines the README shows for it


def _blocks(text: str):
    """(language, first line number, lines) of every fenced block of the README."""
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


def readme_examples() -> list[tuple[int, list[Step]]]:
    """(first line, steps) of every block that is run."""
    out = []
    for language, first, lines in _blocks(README.read_text(encoding="utf-8")):
        steps = _steps(language, first, lines)
        if steps:
            out.append((first, steps))
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
}


def _runner(argv: list[str]):
    for words in sorted(RUNNERS, key=len, reverse=True):
        if argv[:len(words.split())] == words.split():
            return RUNNERS[words]
    return None


def _normalise(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.parametrize("first, steps", readme_examples(),
                         ids=[f"line{first}" for first, _ in readme_examples()])
def test_readme_commands_run(first, steps, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    printed = ""
    skipped = []
    for step in steps:
        command = step.command
        if "../shared/" in command:
            if not SHARED_DIR.is_dir():
                pytest.skip(f"README line {step.line} needs ../shared, not present")
            command = command.replace("../shared/", f"{SHARED_DIR}/")
        argv = shlex.split(command)
        run = _runner(argv)
        assert run is not None, (f"README line {step.line}: no rule to run {step.command!r}; "
                                 "add one to RUNNERS in tests/test_readme.py")
        code, output = run(argv)
        if code is None:
            skipped.append(f"line {step.line}: {output}")
            continue
        assert code == 0, f"README line {step.line}: {step.command!r} exited {code}:\n{output}"
        printed += output
        lines = {_normalise(line) for line in printed.splitlines()}
        for shown in step.expected:
            assert _normalise(shown) in lines, (
                f"README line {step.line}: {step.command!r} did not print {shown!r}; it "
                f"printed:\n{printed}")
    if skipped and len(skipped) == len(steps):
        pytest.skip("; ".join(skipped))


def test_every_readme_command_has_a_rule():
    for _, steps in readme_examples():
        for step in steps:
            argv = shlex.split(step.command)
            assert _runner(argv) is not None, (
                f"README line {step.line}: no rule to run {step.command!r}; add one to "
                "RUNNERS in tests/test_readme.py")


def test_the_parser_finds_the_readme_blocks():
    # guards the parsing above: the blocks this README is known to have are found
    commands = [s.command for _, steps in readme_examples() for s in steps]
    assert "kincal demo" in commands and "pip install ." in commands
    assert any(c.startswith("kincal plan ec66 --random") for c in commands)


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
    """({command: options the 'Command line' section documents for it}, problems).

    A row of the command table whose first cell starts with ``kincal COMMAND`` documents
    the options in that cell for COMMAND; a row of the options table (header ``option |
    commands``) documents the options of its first cell for every command named in its
    second cell.
    """
    section = text.split("\n## Command line", 1)[1].split("\n## ", 1)[0]
    documented = {c: set() for c in commands}
    problems = []
    table_kind = None
    for line in section.splitlines():
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
    text = README.read_text(encoding="utf-8")
    documented, problems = documented_options(text, commands)
    for name, sub in commands.items():
        if not documented[name] and f"`kincal {name}" not in text:
            problems.append(f"kincal {name} has no row in the command table")
        missing = sorted(_options(sub) - documented[name])
        if missing:
            problems.append(f"kincal {name}: options missing from the README's command or "
                            f"option table: {', '.join(missing)}")
        unknown = sorted(documented[name] - _options(sub))
        if unknown:
            problems.append(f"kincal {name}: the README documents options the parser does "
                            f"not have: {', '.join(unknown)}")
    for option in sorted(_options(parser)):  # kincal --version
        if f"kincal {option}" not in text:
            problems.append(f"the README does not mention `kincal {option}`")
    assert not problems, "\n".join(problems)


def test_inline_commands_name_real_options():
    """Every `kincal COMMAND ... --option` span in the README's text uses options the
    parser has for that command (complete ones must parse)."""
    parser = build_parser()
    commands = _subparsers(parser)
    text = README.read_text(encoding="utf-8")
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
    assert not problems, "\n".join(problems)


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


def _poses_csv(path: Path) -> None:
    """The poses.csv of the README's API examples: 25 random EC66 poses with planted
    errors, an offset tool point, 0.02 mm noise, and an acquisition-time column t."""
    import numpy as np
    from conftest import random_joint_values

    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure, planted_table
    from kincal.robot import Robot

    rng = np.random.default_rng(7)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    truth = Truth(planted_table(model, rng), np.array([0.6, 0.2, -0.1, 0.01, -0.02, 0.5]),
                  np.array([0.03, 0.02, 0.12]))
    data = measure(model, truth, random_joint_values(robot.geometry, rng, 25), 2e-5, rng)
    lines = data.to_csv_text().splitlines()
    path.write_text("\n".join([lines[0] + ",t"] + [f"{row},{0.5 * k}" for k, row in
                                                    enumerate(lines[1:])]) + "\n")


def test_readme_python_examples_run(tmp_path, monkeypatch):
    blocks = [(first, lines) for language, first, lines in
              _blocks(README.read_text(encoding="utf-8")) if language == "python"]
    assert blocks, "the README has no Python example"
    monkeypatch.chdir(tmp_path)
    _poses_csv(tmp_path / "poses.csv")
    namespace: dict = {}
    with contextlib.redirect_stdout(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the examples' own warnings are not the point here
        for first, lines in blocks:
            code = compile("\n".join(lines), f"README.md, block at line {first}", "exec")
            exec(code, namespace)  # noqa: S102 - the README's own example code
    assert (tmp_path / "ec66_calibrated.urdf").exists()
