"""mypy on src/kincal, with the settings of pyproject.toml's [tool.mypy]: no error.

mypy is in the ``test`` extra (``pip install .[test]``), so the check runs wherever the
suite does; without mypy this test fails rather than skips. About 15-25 s (a fresh cache
in a temporary folder, so an old cache cannot hide an error).
"""

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_mypy_finds_no_error_in_src(tmp_path):
    assert importlib.util.find_spec("mypy") is not None, (
        "mypy is not installed: it is part of the test extra (pip install '.[test]')")
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
         "--cache-dir", str(tmp_path / "mypy-cache"), "--no-error-summary",
         "--hide-error-context", str(ROOT / "src" / "kincal")],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    errors = [line for line in run.stdout.splitlines() if ": error:" in line]
    assert run.returncode == 0 and not errors, (
        f"mypy found {len(errors)} error(s) in src/kincal:\n" + "\n".join(errors)
        + ("" if errors else f"\n(exit {run.returncode})\n{run.stdout}\n{run.stderr}"))
