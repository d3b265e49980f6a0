"""The compliance term the evidence favours (kincal.identification.term_evidence): on the
real TALOS touches the stance ankle, with a gain that agrees with the nonlinear fits'; on
data simulated without compliance nothing; reported, never fitted."""

import json
import warnings

import numpy as np
import pytest

from kincal import CalibrationOptions, CalibrationProblem, Robot
from kincal.cli.main import main
from kincal.identification import penalty_choice, term_evidence
from kincal.measurements.sets import read_set_file

from test_tree_paths import _talos_study


def _fit(robot, data, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = CalibrationProblem(robot, data, CalibrationOptions(**options))
        problem.analyze()
        sol, fit = penalty_choice.fit_evidence(problem)
    return problem, sol, fit


def test_talos_stance_ankle_is_favoured_as_the_nonlinear_evidence_says(tmp_path, capsys):
    study = _talos_study()
    arm = Robot.load(study.talos_urdf(), base=study.BASE, tip=study.TIP)
    data = read_set_file(study.DATA / "left_train.csv", arm.joint_names, on_plane=True,
                         flush=True)
    problem, sol, fit = _fit(arm, data, tool_guess=(0.0, 0.0, -0.12))
    gains = term_evidence.gains(problem, sol.u, fit)
    assert len(gains) == 15  # the chain's revolute joints with a gravity torque
    gain, joint, size = max(gains)
    assert joint == "leg_left_5_joint" and size < 0
    # linearised at the geometric fit, the gain is what two nonlinear evidence fits give
    _, _, wide = _fit(arm, data, tool_guess=(0.0, 0.0, -0.12), compliance=(joint,))
    nonlinear = wide.log_evidence[-1] - fit.log_evidence[-1]
    assert gain == pytest.approx(nonlinear, abs=1.5) and nonlinear > 15
    found = term_evidence.favoured(problem, sol.u, fit)
    assert found is not None and found.joint == joint
    assert found.threshold_nats == pytest.approx(7 + np.log(15))
    # the command line: a summary line and the JSON, the URDF geometric as before
    out = tmp_path / "c.urdf"
    assert main(["calibrate", str(study.talos_urdf()), str(study.DATA / "left_train.csv"),
                 "--base", study.BASE, "--tip", study.TIP, "--on-plane", "--flush",
                 "--tool-offset", "0", "0", "-0.12", "--out", str(out), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["term_evidence"]["joint"] == joint
    assert summary["term_evidence"]["gain_nats"] == pytest.approx(found.gain_nats, rel=1e-6)
    assert not any(p["name"].endswith(".compliance") for p in summary["parameters"])
    assert main(["calibrate", str(study.talos_urdf()), str(study.DATA / "left_train.csv"),
                 "--base", study.BASE, "--tip", study.TIP, "--on-plane", "--flush",
                 "--tool-offset", "0", "0", "-0.12", "--out", str(out), "--overwrite"]) == 0
    text = capsys.readouterr().out
    assert "diagnosis: the evidence favours a compliance of leg_left_5_joint" in text
    # with the term given, that joint is not tried again, and CV reports none
    problem2, sol2, fit2 = _fit(arm, data, tool_guess=(0.0, 0.0, -0.12), compliance=(joint,))
    assert joint not in {j for _, j, _ in term_evidence.gains(problem2, sol2.u, fit2)}


@pytest.mark.parametrize("kind", ["plane", "pose"])
def test_nothing_is_favoured_without_compliance(tmp_path, kind):
    """Seeds 0-4 of simulated EC66 sets (no compliance planted): no term reported, and the
    gains stay far below the threshold (the null study: scripts/term_evidence_null.py)."""
    robot = Robot.load("ec66")
    path = tmp_path / "sim.csv"
    for seed in range(5):
        assert main(["simulate", "ec66", "--kind", kind, "--poses", "30", "--seed", str(seed),
                     "--out", str(path), "--quiet", "--overwrite"]) == 0
        contact = kind == "plane"
        data = read_set_file(path, robot.joint_names, on_plane=contact)
        problem, sol, fit = _fit(robot, data, lam="evidence",
                                 tool_guess=(0.0, 0.0, 0.1) if contact else None)
        gains = term_evidence.gains(problem, sol.u, fit)
        assert gains and max(gains)[0] < 7.0
        assert term_evidence.favoured(problem, sol.u, fit) is None


def test_only_after_an_evidence_fit(tmp_path):
    """CV (or a given lambda) and robust losses leave term_evidence None: the comparison is
    the evidence's own."""
    path = tmp_path / "sim.csv"
    assert main(["simulate", "ec66", "--kind", "plane", "--poses", "30", "--seed", "1",
                 "--out", str(path), "--quiet"]) == 0
    robot = Robot.load("ec66")
    data = read_set_file(path, robot.joint_names, on_plane=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for options in ({"lam": "cv"}, {"lam": 1.0}, {"lam": "evidence", "robust": "huber"}):
            result = CalibrationProblem(robot, data, CalibrationOptions(
                tool_guess=(0.0, 0.0, 0.1), **options)).solve()
            assert result.term_evidence is None
