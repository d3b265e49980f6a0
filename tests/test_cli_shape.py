"""The command line's shape: a dispatcher, one module per command, `python -m kincal`."""

import importlib
import subprocess
import sys
from pathlib import Path

cli_main = importlib.import_module("kincal.cli.main")

CLI = Path(cli_main.__file__).parent


def test_main_is_a_dispatcher_of_one_module_per_command():
    assert len((CLI / "main.py").read_text().splitlines()) < 200
    names = [m.__name__.rsplit(".", 1)[1] for m in cli_main.COMMANDS]
    assert names == ["calibrate", "evaluate", "analyze", "simulate", "plan", "compensate", "demo",
                     "fleet"]
    sub = next(a for a in cli_main.build_parser()._actions if hasattr(a, "choices")
               and isinstance(a.choices, dict))
    for name in names:
        module = importlib.import_module(f"kincal.cli.{name}")
        assert callable(module.register) and callable(module.run)
        assert sub.choices[name].get_default("run") is module.run


def test_no_module_outside_cli_takes_a_namespace():
    src = CLI.parent
    for path in src.rglob("*.py"):
        if CLI in path.parents:
            continue
        assert "argparse" not in path.read_text(encoding="utf-8"), path


def test_help_is_grouped():
    text = cli_main.build_parser()._subparsers._group_actions[0].choices["calibrate"].format_help()
    for title in ("inputs:", "chain:", "model and penalty:", "outputs:"):
        assert title in text


def test_every_option_says_what_it_does():
    # `kincal COMMAND --help` is the prompt's reference (docs/cli.md says it says the same):
    # an option listed there without a word (as --method was, its `frames` choice
    # documented nowhere) leaves the reader to guess
    sub = cli_main.build_parser()._subparsers._group_actions[0].choices
    silent = [f"kincal {name} {action.option_strings[-1]}" for name, parser in sub.items()
              for action in parser._actions
              if action.option_strings and action.help is None]
    assert not silent, f"options without help: {silent}"


def test_python_dash_m_kincal():
    out = subprocess.run([sys.executable, "-m", "kincal", "--version"], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.startswith("kincal ")
