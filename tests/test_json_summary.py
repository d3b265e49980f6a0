"""--json on every command with a summary: one JSON object, alone on stdout, whose numbers
are the human summary's and the files'."""

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from kincal.cli.main import main

EC66 = Path(__file__).resolve().parents[1] / "urdf" / "ec66.urdf"


def _json(capsys, *argv) -> dict:
    """Run ``kincal argv --json``; the whole of stdout must be one JSON object."""
    capsys.readouterr()
    assert main([*map(str, argv), "--json"]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert out["format"] == "kincal-summary-1" and out["command"] == str(argv[0])
    for path in out["written"]:  # said on stderr instead of stdout
        assert f"kincal: wrote {path}" in cap.err
    return out


def _human(capsys, *argv) -> str:
    capsys.readouterr()
    assert main([*map(str, argv)]) == 0
    return capsys.readouterr().out


def _rows(path) -> list[dict]:
    with open(path, newline="") as f:
        return list(csv.DictReader(line for line in f if not line.startswith("#")))


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    """Simulated data, a calibration and its frames."""
    d = tmp_path_factory.mktemp("json")
    assert main(["simulate", "ec66", "--out", str(d / "cal.csv"), "--poses", "30", "--seed", "4",
                 "--tool-m", "0.03", "0.02", "0.1", "-q"]) == 0
    assert main(["calibrate", str(EC66), str(d / "cal.csv"), "--tip", "flange", "--lambda",
                 "0.01", "--out", str(d / "c.urdf"), "--frames-out", str(d / "f.json"),
                 "-q"]) == 0
    return d


def test_simulate_and_plan(cell, tmp_path, capsys):
    out = _json(capsys, "simulate", "ec66", "--out", tmp_path / "s.csv", "--poses", 17,
                "--seed", 3, "--noise-mm", 0.02)
    assert out["poses"] == 17 == len(_rows(tmp_path / "s.csv"))
    assert out["noise_m"] == pytest.approx(2e-5) and out["seed"] == 3 and out["kind"] == "point"
    assert out["written"] == [str(tmp_path / "s.csv")]
    argv = ("plan", "ec66", "--random", 300, "--poses", 9, "--out", tmp_path / "p.csv",
            "--overwrite")
    human = _human(capsys, *argv)
    out = _json(capsys, *argv)
    rows = _rows(tmp_path / "p.csv")
    assert out["chosen"] == 9 == len(rows)
    q = np.array([[float(r[j]) for j in out["joint_names"]] for r in rows])
    np.testing.assert_allclose(out["joint_values_si"], q, rtol=0, atol=1e-15)
    chosen = re.search(r"log det \(normalised information\): (\S+) chosen", human)
    assert f"{out['log_det']:.2f}" == chosen.group(1)
    worst = max(out["std_errors"], key=lambda s: s["std_error"])  # the human table's first row
    assert re.search(rf"{re.escape(worst['name'])}\s+{worst['std_error']:.4g}\s", human)


def test_evaluate_and_analyze(cell, tmp_path, capsys):
    argv = ("evaluate", cell / "c.urdf", cell / "cal.csv", "--frames", cell / "f.json")
    human = _human(capsys, *argv)
    out = _json(capsys, *argv, "--report", tmp_path / "e.json")
    mean = re.search(r"mean ([0-9.]+)  max", human).group(1)  # ErrorStats.line()
    assert f"{out['errors']['mean_mm']:.3f}" == f"{float(mean):.3f}"
    report = json.loads((tmp_path / "e.json").read_text())
    assert report["errors"] == out["errors"] and report["kind"] == out["kind"] == "point"
    argv = ("analyze", EC66, cell / "cal.csv", "--tip", "flange")
    human = _human(capsys, *argv)
    out = _json(capsys, *argv, "--report", tmp_path / "a.json")
    report = json.loads((tmp_path / "a.json").read_text())
    ident = out["identifiability"]
    assert ident["rank"] == report["rank"] and ident["kept"] == report["kept"]
    assert f"rank {ident['rank']}" in human and out["accuracy_map"] is None


def test_compensate(cell, tmp_path, capsys):
    out = _json(capsys, "compensate", cell / "c.urdf", "--program", cell / "cal.csv",
                "--nominal", EC66, "--frames", cell / "f.json", "--tip", "flange", "--out",
                tmp_path / "j.csv")
    rows = _rows(tmp_path / "j.csv")
    assert out["targets"] == out["reached"] == len(rows) == 30 and out["not_reached"] == []
    q = np.array([[float(r[j]) for j in out["joint_names"]] for r in rows])
    np.testing.assert_allclose(out["joint_values_si"], q, rtol=1e-12, atol=1e-15)
    assert 0 <= out["max_position_error_m"] < 1e-6  # within --tolerance-mm (0.001 mm)


def test_fleet(cell, tmp_path, capsys):
    files = []
    for seed in (1, 2):
        f = tmp_path / f"u{seed}.csv"
        assert main(["simulate", "ec66", "--out", str(f), "--poses", "30", "--seed", str(seed),
                     "--tool-m", "0.03", "0.02", "0.1", "-q"]) == 0
        files.append(f)
    out = _json(capsys, "fleet", EC66, *files, "--tip", "flange", "--out-dir", tmp_path / "fl")
    summary = json.loads((tmp_path / "fl" / "FLEET_SUMMARY.json").read_text())
    assert out["units"] == summary["units"] and out["parameters"] == summary["parameters"]
    assert [u["status"] for u in out["units"]] == ["calibrated", "calibrated"]
    assert sorted(Path(p).name for p in out["written"]) == ["FLEET.json", "FLEET_SUMMARY.json",
                                                             "fleet.html"]
