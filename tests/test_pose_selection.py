"""D-optimal pose selection: criterion, search, honesty about identifiability, CSV and CLI."""

import math
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import ur10_path

from kincal.cli.main import main
from kincal.errors import DataError, InputFileError, OptionError, ParameterError
from kincal.identification.problem import CalibrationOptions, CalibrationProblem, calibrate
from kincal.measurements.point_space import MM, ParameterSpace
from kincal.identification.selection import analyze
from kincal.measurements.point import MeasurementModel
from kincal import models
from kincal.models import mdh
from kincal.planning.candidates import random_candidates, read_candidates
from kincal.planning.pose_selection import EXCHANGE_TOL, select_poses
from kincal.planning.simulation import Truth, measure, planted_table, true_positions
from kincal.robot import Robot

TOOL = (0.03, 0.02, 0.12)  # [m] a tool point well off the last axis


@pytest.fixture(scope="module")
def ec66():
    return Robot.load("ec66", tip="flange")


@pytest.fixture(scope="module")
def ur10():
    ur10_path()  # skips without example-robot-data
    return Robot.load("ur10", tip="tool0")


@pytest.fixture(scope="module", params=["ec66", "ur10"])
def case(request, ec66):
    robot = ec66 if request.param == "ec66" else request.getfixturevalue("ur10")
    candidates = random_candidates(robot, 400, np.random.default_rng(7))
    return robot, candidates, select_poses(robot, candidates, 20, tool=TOOL)


def _normalised_jacobian(robot, candidates, selection, tool=TOOL):
    """Jacobian of the candidates in the criterion's columns, built independently."""
    model = models.build(models.DEFAULT, robot.geometry)  # select_poses' default model
    space = ParameterSpace.of_model(model)
    x = space.join(model.nominal, np.zeros(6), np.asarray(tool))
    J = MeasurementModel(model, candidates).jacobian(x)[1] * (space.reporting_scale() / MM)
    cols = space.indices(selection.parameters)
    return J, J[:, :, cols] / selection.column_scale, space


def _log_det(Jn, rows):
    X = Jn[list(rows)].reshape(-1, Jn.shape[2])
    sign, value = np.linalg.slogdet(X.T @ X)
    return value if sign > 0 else -np.inf


# ------------------------------------------------------------------ criterion
def test_beats_random_subsets_and_the_greedy_stage(case):
    robot, candidates, s = case
    assert s.log_det > s.random_log_det
    assert s.log_det >= s.greedy_log_det - 1e-9
    assert s.exchange_converged
    # an independent baseline: our own random subsets, our own determinants
    _, Jn, _ = _normalised_jacobian(robot, candidates, s)
    rng = np.random.default_rng(99)
    ours = [_log_det(Jn, rng.choice(len(candidates), 20, replace=False)) for _ in range(20)]
    assert s.log_det > np.max(ours)
    greedy = select_poses(robot, candidates, 20, tool=TOOL, max_swaps=0)
    assert greedy.log_det == pytest.approx(s.greedy_log_det, rel=1e-12)
    assert s.log_det >= greedy.log_det - 1e-9


def test_same_call_same_poses(case):
    robot, candidates, s = case
    again = select_poses(robot, candidates.copy(), 20, tool=TOOL)
    assert again.indices == s.indices and again.log_det == s.log_det
    assert len(set(s.indices)) == 20
    assert np.array_equal(s.joint_values, candidates[list(s.indices)])


def test_tracked_log_det_and_variances_equal_direct_computation(case):
    robot, candidates, s = case
    J, Jn, space = _normalised_jacobian(robot, candidates, s)
    direct = _log_det(Jn, s.indices)
    assert abs(s.log_det - direct) <= 1e-8 * abs(direct)
    # predicted std errors: sqrt(diag((J^T J)^-1)) sigma in mm / deg, unnormalised columns
    X = J[list(s.indices)][:, :, space.indices(s.parameters)].reshape(-1, len(s.parameters))
    se = np.sqrt(np.diag(np.linalg.inv(X.T @ X))) * 0.05
    np.testing.assert_allclose(s.std_errors(0.05), se, rtol=1e-8)
    assert s.units[s.parameters.index("joint_2.theta" if robot.name == "ec66"
                                      else "shoulder_lift_joint.theta")] == "deg"
    assert s.units[s.parameters.index("tool.z")] == "mm"
    C = X.T @ X
    d = np.sqrt(np.diag(C))
    w = np.linalg.eigvalsh(C / np.outer(d, d))
    assert s.condition == pytest.approx(w[-1] / w[0], rel=1e-6)


def test_chosen_poses_identify_what_the_candidates_identify(case):
    robot, candidates, s = case
    J, _, space = _normalised_jacobian(robot, candidates, s)
    all_ = analyze(J.reshape(-1, space.size), space.names, space.n_kinematic)
    mine = analyze(J[list(s.indices)].reshape(-1, space.size), space.names, space.n_kinematic)
    assert mine.kept == all_.kept == s.parameters
    assert s.lost == () and len(s.parameters) == 27  # 25 MD-H + 2 betas (complete model)
    # and so says the calibration's own analysis, on measurements of the chosen poses
    model = mdh.extract(robot.geometry)
    truth = Truth(model.table, np.array([0.7, 0.2, -0.1, 0.01, 0.02, 0.4]), np.array(TOOL))
    data = measure(model, truth, s.joint_values, 0.0, np.random.default_rng(0))
    problem = CalibrationProblem(robot, data, CalibrationOptions(method="ls"))
    assert problem.analyze().kept == s.parameters


def test_exchange_ends_in_a_local_optimum_brute_force(ec66):
    candidates = random_candidates(ec66, 40, np.random.default_rng(3))
    s = select_poses(ec66, candidates, 10, tool=TOOL)
    _, Jn, _ = _normalised_jacobian(ec66, candidates, s)
    here = _log_det(Jn, s.indices)
    best = max(_log_det(Jn, s.indices[:i] + (j,) + s.indices[i + 1:])
               for i in range(10) for j in range(40) if j not in s.indices)
    assert best <= here + EXCHANGE_TOL + 1e-9 * abs(here)
    assert s.swaps > 0  # the exchange had work to do on this case


def test_keep_comes_first_and_stays(ec66):
    candidates = random_candidates(ec66, 200, np.random.default_rng(4))
    s = select_poses(ec66, candidates, 12, tool=TOOL, keep=[5, 17])
    assert s.indices[:2] == (5, 17) and len(set(s.indices)) == 12


def test_fix_leaves_parameters_out(ec66):
    candidates = random_candidates(ec66, 200, np.random.default_rng(4))
    s = select_poses(ec66, candidates, 12, tool=TOOL, fix=("tool.x", "tool.y", "tool.z"))
    assert s.fixed == ("tool.x", "tool.y", "tool.z")
    assert not set(s.fixed) & set(s.parameters)
    assert "joint_6.d" in s.parameters  # no longer a duplicate of tool.z
    text = s.summary(0.02)
    assert "fixed by the user: tool.x" in text and "a noise of 0.02 mm per axis:" in text


def test_predicted_errors_name_each_kinds_noise(ec66):
    """The noise the predicted errors are for, per row of the kind: a pose's orientation
    rows weigh 0.01 deg against 0.05 mm (the pose sets' default), one distance per pose."""
    candidates = random_candidates(ec66, 60, np.random.default_rng(4))
    pose = select_poses(ec66, candidates, 12, tool=TOOL, kind="pose", random_subsets=2)
    assert "a noise of 0.1 mm per axis and 0.02 deg per orientation axis:" in pose.summary(0.1)
    dist = select_poses(ec66, candidates, 40, tool=TOOL, kind="distance", random_subsets=2,
                        pivot=(0.4, 0.0, 0.2))
    assert "a noise of 0.05 mm per distance:" in dist.summary()


def test_tool_on_last_axis_warns(ec66):
    candidates = random_candidates(ec66, 100, np.random.default_rng(4))
    with pytest.warns(UserWarning, match="axis of joint_6"):
        select_poses(ec66, candidates, 12)


def test_random_candidates_respect_limits(ec66):
    q = random_candidates(ec66, 500, 1)
    g = ec66.geometry
    assert q.shape == (500, 6) and np.all(q >= g.lower) and np.all(q <= g.upper)
    assert np.array_equal(q, random_candidates(ec66, 500, 1))
    from kincal.models.geometry import ChainGeometry

    unlimited = SimpleNamespace(geometry=ChainGeometry(
        ("a", "b"), ("revolute", "revolute"), np.tile(np.eye(4), (2, 1, 1)),
        np.array([[0.0, 0.0, 1.0]] * 2), np.eye(4), lower=np.array([-np.inf, 0.0]),
        upper=np.array([np.inf, 0.5])), joint_names=("a", "b"), mimics={})
    q = random_candidates(unlimited, 2000, 0)
    assert -np.pi <= q[:, 0].min() < -3.0 and 3.0 < q[:, 0].max() <= np.pi
    assert 0.0 <= q[:, 1].min() and q[:, 1].max() <= 0.5


# --------------------------------------------------------------------- errors
def test_bad_requests_raise_clear_errors(ec66):
    candidates = random_candidates(ec66, 50, np.random.default_rng(5))
    with pytest.raises(OptionError, match=r"identify 27 parameters.*at least 9 poses"):
        select_poses(ec66, candidates, 8, tool=TOOL)
    with pytest.raises(OptionError, match="cannot choose 51 poses from 50 candidates"):
        select_poses(ec66, candidates, 51, tool=TOOL)
    bad = candidates.copy()
    bad[13, 2] = np.nan
    with pytest.raises(DataError, match=r"candidate row 13 .* joint_3"):
        select_poses(ec66, bad, 10, tool=TOOL)
    with pytest.raises(DataError, match=r"\(M, 6\)"):
        select_poses(ec66, candidates[:, :5], 10, tool=TOOL)
    with pytest.raises(ParameterError, match="joint_9.a"):
        select_poses(ec66, candidates, 10, tool=TOOL, fix=("joint_9.a",))
    with pytest.raises(OptionError, match="expected one of D"):
        select_poses(ec66, candidates, 10, tool=TOOL, method="A")
    with pytest.raises(OptionError, match="keep"):
        select_poses(ec66, candidates, 10, tool=TOOL, keep=[50])
    with pytest.raises(OptionError, match="tool"):
        select_poses(ec66, candidates, 10, tool=(0.0, 0.1))


def _write(path, text):
    path.write_text(text)
    return path


def test_candidate_csv_reader(ec66, tmp_path):
    q, lines = read_candidates(_write(tmp_path / "c.csv", "note,joint_1,joint_2,joint_3,joint_4,"
                                      "joint_5,joint_6\na,10,20,30,40,50,60\n\nb,0,0,0,0,0,-90\n"),
                               ec66, angle_unit="deg")
    np.testing.assert_allclose(q, np.radians([[10, 20, 30, 40, 50, 60], [0, 0, 0, 0, 0, -90]]))
    assert lines.tolist() == [2, 4]  # line numbers of the file, blank lines counted
    header = "joint_1,joint_2,joint_3,joint_4,joint_5,joint_6\n"
    with pytest.raises(DataError, match=r"line 4, column 'joint_3': 'x'"):
        read_candidates(_write(tmp_path / "d.csv", header + "0,0,0,0,0,0\n\n0,0,x,0,0,0\n"), ec66)
    with pytest.raises(DataError, match=r"line 2, column 'joint_6': an empty cell"):
        read_candidates(_write(tmp_path / "e.csv", header + "0,0,0,0,0,\n"), ec66)
    with pytest.raises(DataError, match=r"missing column\(s\) joint_6.*Did you mean 'joint6'"):
        read_candidates(_write(tmp_path / "f.csv", header.replace("joint_6", "joint6") + "0,0,0,0,0,0\n"),
                        ec66)
    with pytest.raises(DataError, match="a header but no poses"):
        read_candidates(_write(tmp_path / "g.csv", header), ec66)
    with pytest.raises(DataError, match="empty"):
        read_candidates(_write(tmp_path / "h.csv", ""), ec66)
    with pytest.raises(DataError, match="line 2: 5 cells"):
        read_candidates(_write(tmp_path / "i.csv", header + "0,0,0,0,0\n"), ec66)
    with pytest.raises(InputFileError, match="not found"):
        read_candidates(tmp_path / "nope.csv", ec66)
    with pytest.warns(UserWarning, match=r"outside its URDF limits.*line 2"):
        read_candidates(_write(tmp_path / "j.csv", header + "0,0,0,0,0,6.5\n"), ec66)


# ------------------------------------------------------------------------ CLI
def _one_line_error(capsys):
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("kincal: error:")]
    assert len(err) == 1
    return err[0]


def test_cli_plan_writes_the_chosen_poses_and_refuses_to_overwrite(ec66, tmp_path, capsys):
    candidates = random_candidates(ec66, 300, np.random.default_rng(8))
    src = tmp_path / "candidates.csv"
    src.write_text("joint_1,joint_2,joint_3,joint_4,joint_5,joint_6\n" + "\n".join(
        ",".join(repr(float(v)) for v in row) for row in np.degrees(candidates)) + "\n")
    out = tmp_path / "chosen.csv"
    args = ["plan", "ec66", str(src), "--tip", "flange", "--poses", "15", "--out", str(out),
            "--angle-unit", "deg", "--tool-offset", "30", "20", "120", "--length-unit", "mm",
            "--noise-mm", "0.02", "--criterion", "d"]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "D-optimal selection of 15 of 300" in text and "random median" in text
    assert "a noise of 0.02 mm per axis" in text and "deg" in text and "wrote" in text
    lines = _rows(out)
    assert lines[0] == "joint_1,joint_2,joint_3,joint_4,joint_5,joint_6,candidate_line"
    assert len(lines) == 16
    table = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    expected = select_poses(ec66, np.radians(np.degrees(candidates)), 15, tool=TOOL)
    np.testing.assert_allclose(table[:, :6], expected.joint_values, rtol=0, atol=1e-12)  # SI
    assert table[:, 6].tolist() == [i + 2 for i in expected.indices]  # line in the candidates
    before = out.read_bytes()
    assert main(args) == 1
    assert "already exists" in _one_line_error(capsys) and out.read_bytes() == before
    assert main(args + ["--overwrite"]) == 0
    capsys.readouterr()
    assert main(args[:-4] + ["--out", str(src), "--noise-mm", "0.02"]) == 1  # the input
    assert "input file" in _one_line_error(capsys)


def test_cli_plan_random_candidates_and_option_errors(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert main(["plan", "ec66", "--random", "200", "--seed", "2", "--poses", "12",
                 "--tool-offset", "0.03", "0.02", "0.12", "--out", str(out)]) == 0
    assert "200 random candidates" in capsys.readouterr().out
    assert len(_rows(out)) == 13
    assert main(["plan", "ec66", "--poses", "12", "--out", str(tmp_path / "a.csv")]) == 1
    assert "exactly one of" in _one_line_error(capsys)
    assert main(["plan", "ec66", str(out), "--random", "50", "--poses", "12",
                 "--out", str(tmp_path / "b.csv")]) == 1
    assert "exactly one of" in _one_line_error(capsys)
    assert main(["plan", "ec66", "--random", "50", "--poses", "3", "--tool-offset", "0.03",
                 "0.02", "0.12", "--out", str(tmp_path / "c.csv")]) == 1
    assert "at least 9 poses" in _one_line_error(capsys)
    assert main(["plan", "ec66", str(tmp_path / "missing.csv"), "--poses", "12",
                 "--out", str(tmp_path / "d.csv")]) == 1
    assert "not found" in _one_line_error(capsys)
    assert not any((tmp_path / n).exists() for n in ("a.csv", "b.csv", "c.csv", "d.csv"))


# ------------------------------------------------------------------- recovery
def test_d_optimal_poses_calibrate_better_than_random_ones(ec66):
    """Simulated EC66, 30 poses from the same 500 candidates, plain LS, held-out error.

    Each seed averages 3 noise draws (and 3 random subsets), because with 30 poses one
    noise draw moves the held-out error by as much as the choice of poses does.
    """
    model = mdh.extract(ec66.geometry)
    tool = np.array(TOOL)
    d_opt, rand, se_d, se_r = [], [], [], []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        candidates = random_candidates(ec66, 500, rng)
        truth = Truth(planted_table(model, rng), np.array([0.8, 0.3, -0.2, 0.01, -0.03, 1.0]), tool)
        held_out = random_candidates(ec66, 200, rng)
        P = true_positions(model, truth, held_out)
        s = select_poses(ec66, candidates, 30, tool=TOOL)
        se_d.append(np.exp(np.mean(np.log(s.std_errors(0.05)))))
        se_r.append(np.exp(np.mean(np.log(s.random_std_errors(0.05)))))

        def error(rows):
            data = measure(model, truth, candidates[rows], 0.05e-3, rng)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = calibrate(ec66, data, method="ls", tool_guess=TOOL)
            return float(np.mean(np.linalg.norm(result.predict(held_out) - P, axis=1)))

        d_opt.append(np.mean([error(list(s.indices)) for _ in range(3)]))
        rand.append(np.mean([error(rng.choice(500, 30, replace=False)) for _ in range(3)]))
    assert np.mean(d_opt) < np.mean(rand)
    assert all(a < b for a, b in zip(se_d, se_r))
    assert math.isfinite(np.mean(d_opt)) and np.mean(d_opt) < 1e-4  # [m], 0.1 mm


def test_cli_plan_complements_poses_already_measured(tmp_path, capsys):
    ec66 = Robot.load("ec66", tip="flange")
    rng = np.random.default_rng(11)
    measured = random_candidates(ec66, 12, rng)
    header = ",".join(ec66.joint_names)
    done = tmp_path / "measured.csv"  # as a measurement file: extra x, y, z columns
    done.write_text(header + ",x,y,z\n" + "\n".join(
        ",".join(repr(float(v)) for v in row) + ",0,0,0" for row in measured) + "\n")
    cands = random_candidates(ec66, 300, rng)
    src = tmp_path / "candidates.csv"
    src.write_text(header + "\n" + "\n".join(",".join(repr(float(v)) for v in row)
                                             for row in cands) + "\n")
    out = tmp_path / "new.csv"
    assert main(["plan", "ec66", str(src), "--measured", str(done), "--poses", "10",
                 "--tool-offset", "0.03", "0.02", "0.12", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "plus the 12 poses already measured" in text and "10 new" in text
    assert "I-optimal selection of 22" in text and "target poses: the candidates" in text
    table = np.array([[float(v) for v in line.split(",")] for line in _rows(out)[1:]])
    expected = select_poses(ec66, np.vstack([measured, cands]), 22, tool=TOOL, keep=range(12),
                            method="I", targets=cands)  # the default: the candidates as targets
    assert list(expected.indices[:12]) == list(range(12))
    new = [i - 12 for i in expected.indices[12:]]
    np.testing.assert_allclose(table[:, :6], cands[new], rtol=0, atol=1e-12)
    assert table[:, 6].tolist() == [i + 2 for i in new]


def test_cli_plan_with_a_missing_measured_file_writes_nothing(tmp_path, capsys):
    out = tmp_path / "new.csv"
    assert main(["plan", "ec66", "--random", "100", "--poses", "10", "--measured",
                 str(tmp_path / "nope.csv"), "--out", str(out)]) == 1
    assert "measured poses file not found" in _one_line_error(capsys) and not out.exists()


def test_target_poses_are_for_point_measurements(ec66, tmp_path, capsys):
    """I-optimal selection weighs the predicted tool-point position: asked for another kind
    it is refused in one line (it used to fail with an UnboundLocalError)."""
    q = random_candidates(ec66, 200, 1)
    with pytest.raises(OptionError, match="for --kind point, not 'pose'"):
        select_poses(ec66, q, 12, tool=TOOL, targets=q[:20], method="I", kind="pose")
    capsys.readouterr()
    assert main(["plan", "ec66", "--random", "200", "--poses", "12", "--kind", "pose",
                 "--criterion", "i", "--target-cube", "0.4", "0", "0.3", "0.2",
                 "--out", str(tmp_path / "p.csv")]) == 1
    err = capsys.readouterr().err.splitlines()
    assert [e for e in err if e.startswith("kincal: error:")][0].endswith("not 'pose'")
    assert not (tmp_path / "p.csv").exists()


def _rows(path) -> list[str]:
    """Header and rows of the CSV plan wrote, without its provenance (# lines)."""
    return [r for r in path.read_text().splitlines() if not r.startswith("#")]


def test_a_set_singular_by_its_condition_has_no_finite_log_det():
    """A chosen set whose information is singular by the condition (variances inf) was
    reported with a finite log det beside condition inf (TALOS flush, 19 of 21 touches:
    -169.96 chosen, -inf random)."""
    from kincal.planning.pose_selection import _set_figures

    rng = np.random.default_rng(0)
    J = rng.normal(size=(6, 2, 3))
    J[:, :, 2] = J[:, :, 1] + 1e-9 * rng.normal(size=(6, 2))  # two columns nearly alike
    ld, cond, var = _set_figures(J, np.ones(3), np.array([[0, 1, 2, 3, 4, 5], [0, 1, 2, 3, 4, 5]]))
    assert np.all(np.isinf(cond)) and np.all(np.isinf(var)) and np.all(ld == -np.inf)
    J[:, :, 2] = rng.normal(size=(6, 2))  # well conditioned: finite figures
    ld, cond, var = _set_figures(J, np.ones(3), np.array([[0, 1, 2, 3, 4, 5]]))
    assert np.isfinite(ld[0]) and np.isfinite(cond[0]) and np.all(np.isfinite(var))
