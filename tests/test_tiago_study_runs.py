"""scripts/tiago_mocap.py, the study behind docs/results.md's TIAGo figures, runs on the
landed code (it reaches into the problem's internals, so an API change can break it
unseen: it did once). Its quickest mode, checked for its own cross-check against
kincal.CalibrationProblem and for the row the CV selects."""

import re
import subprocess
import sys

from conftest import REPO, tiago_urdf


def test_the_tiago_study_runs_and_agrees_with_kincal():
    tiago_urdf()  # skips without ../shared
    out = subprocess.run([sys.executable, str(REPO / "scripts" / "tiago_mocap.py"), "--quick"],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    agree = re.search(r"held-out predictions agree to ([0-9.e+-]+) mm", out.stdout)
    assert agree and float(agree.group(1)) < 1e-9, out.stdout[-3000:]
    selected = re.search(r"\| ([^|]*)\*\*\(selected by CV\)\*\* \|", out.stdout)
    assert selected and "backlash arm_6" in selected.group(1), out.stdout[-3000:]
    # its closing notes called compliance terms a prototype long after --compliance landed
    proposals = out.stdout.split("Prototyped here only")[1]
    assert "ompliance" not in proposals and "`--compliance JOINT`" in out.stdout
