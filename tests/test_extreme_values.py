"""Extreme but finite values (issue 24, class 1, and the absurd sigmas of class 2): each is
refused at the boundary with one ``kincal: error:`` line naming the accepted range, exit
code 1, no traceback, no foreign stderr line, and the folder left as it was."""

import re
import shutil

import numpy as np

import pytest

from kincal.cli.main import main
from kincal.errors import DataError, OptionError
from kincal.identification.evidence import estimate
from kincal.identification.options import CalibrationOptions
from kincal.identification.solver import SolverOptions, solve
from kincal.measurements.kind import check_sigmas



@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Point and pose files of a simulated EC66 (R-test design: a 20 mm cube)."""
    d = tmp_path_factory.mktemp("made")
    for kind in ("point", "pose"):
        assert main(["simulate", "ec66", "--out", str(d / f"{kind}.csv"), "--design", "rtest",
                     "--seed", "1", "--kind", kind]) == 0
    return d


def _snapshot(folder):
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(folder.iterdir())}


def _refused(argv, folder, capsys, code=1):
    """Run kincal with ``argv`` in ``folder``; assert the refusal; return the error line."""
    capsys.readouterr()
    before = _snapshot(folder)
    got = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert not any("Traceback" in e for e in err), err
    assert all(e.startswith("kincal:") for e in err), f"a foreign stderr line: {err}"
    lines = [e for e in err if e.startswith("kincal: error:")]
    assert got == code and len(lines) == 1, (got, err)
    assert _snapshot(folder) == before, "the folder changed on a refusal"
    return lines[0]


def _data(made, tmp_path, kind="point", edit=None, name=None):
    """A copy of the made file in tmp_path, each data line passed through ``edit``."""
    path = tmp_path / (name or f"{kind}.csv")
    if edit is None:
        shutil.copy(made / f"{kind}.csv", path)
    else:
        header, *rows = _uncommented(made / f"{kind}.csv")
        new_header, _ = edit(header, None)
        path.write_text("\n".join([new_header] + [edit(None, r)[1] for r in rows]) + "\n")
    return path


def _uncommented(path) -> list[str]:
    """The header and rows of a CSV kincal wrote, without its provenance (# lines)."""
    return [line for line in path.read_text().splitlines() if not line.startswith("#")]


def _calibrate(path, tmp_path, *extra):
    return ["calibrate", "ec66", str(path), "--out", str(tmp_path / "C.urdf"), *extra]


# --------------------------------------------------- evidence settings at 1e+-300
@pytest.mark.parametrize("flag", ["--prior-mm", "--prior-deg", "--noise-mm"])
@pytest.mark.parametrize("value", ["1e300", "1e-300"])
def test_evidence_settings_far_out_of_range_are_refused(flag, value, made, tmp_path, capsys):
    path = _data(made, tmp_path)
    line = _refused(_calibrate(path, tmp_path, flag, value), tmp_path, capsys)
    assert flag in line and "between 1e-06 and 10000" in line


@pytest.mark.parametrize("key", ["prior_mm", "prior_deg", "noise_mm"])
def test_evidence_settings_at_the_ends_of_the_range_are_accepted(key):
    for value in (1e-6, 1e4):
        CalibrationOptions(lam="evidence", **{key: value}).validated()
    for value in (0.99e-6, 1.01e4):
        with pytest.raises(OptionError, match="between"):
            CalibrationOptions(lam="evidence", **{key: value}).validated()


# ------------------------------------------------------------------ sigma values
def _with_sigma(value):
    def edit(header, row):
        return (header + ",sigma" if header else None), (row + f",{value}" if row else None)
    return edit


@pytest.mark.parametrize("value", ["1e300", "1e-320"])
def test_sigma_column_far_out_of_range_is_refused(value, made, tmp_path, capsys):
    path = _data(made, tmp_path, edit=_with_sigma(value))
    line = _refused(_calibrate(path, tmp_path), tmp_path, capsys)
    assert "line 2, column 'sigma'" in line and "accepted range" in line


@pytest.mark.parametrize("value", ["1e300", "1e-300"])
def test_set_sigma_far_out_of_range_is_refused_for_pose_files(value, made, tmp_path, capsys):
    path = _data(made, tmp_path, "pose")
    line = _refused(_calibrate(path, tmp_path, "--set-sigma-mm", value), tmp_path, capsys)
    assert "sigma" in line and "accepted range 1e-06 mm to 1000 mm" in line


@pytest.mark.parametrize("value", ["1e300", "1e-300"])
def test_set_sigma_far_out_of_range_is_refused_for_point_files(value, made, tmp_path, capsys):
    path = _data(made, tmp_path)
    line = _refused(_calibrate(path, tmp_path, "--set-sigma-mm", value), tmp_path, capsys)
    assert "--set-sigma-mm" in line


def test_orientation_sigma_far_out_of_range_is_refused(made, tmp_path, capsys):
    path = _data(made, tmp_path, "pose")
    line = _refused(_calibrate(path, tmp_path, "--orientation-sigma-deg", "1e-300"),
                    tmp_path, capsys)
    assert "orientation sigma must be between 1e-06 and 90 deg" in line


def test_sigma_range_ends():
    check_sigmas([1e-9, 1.0], 2, "mem")  # 1 nm and 1 m are accepted
    check_sigmas([1e-6, 90.0], 2, "mem", "sigma_deg", "deg")
    for bad in (0.99e-9, 1.01, 0.0, -1.0, np.nan, np.inf):
        with pytest.raises(DataError, match="accepted range"):
            check_sigmas([1e-4, bad], 2, "mem", rows=[2, 3])


# ------------------------------------------------------------- degenerate files
def test_positions_all_zero_are_refused(made, tmp_path, capsys):
    def edit(header, row):
        return header, (",".join(row.split(",")[:6] + ["0", "0", "0"]) if row else None)

    path = _data(made, tmp_path, edit=edit)
    line = _refused(_calibrate(path, tmp_path), tmp_path, capsys)
    assert "position" in line


def _three_poses(made, tmp_path):
    header, *rows = _uncommented(made / "point.csv")
    path = tmp_path / "three.csv"
    path.write_text("\n".join([header] + rows[:3]) + "\n")
    return path


def test_three_poses_from_a_small_volume_are_refused(made, tmp_path, capsys):
    path = _three_poses(made, tmp_path)
    _refused(_calibrate(path, tmp_path), tmp_path, capsys)


def test_evidence_fit_with_every_parameter_flat():
    """No penalised parameter is free (3 poses leave only the frames): the evidence fit
    is plain least squares with an estimated noise, not an IndexError."""
    rng = np.random.default_rng(3)
    A = rng.normal(size=(9, 4))
    b = rng.normal(size=9)
    u0 = np.zeros(4)

    def fit(weights, u_start, row_scale):
        assert not weights.any()
        return solve(lambda u, jac: (A @ u - b, A if jac else None), u_start, np.ones(4, bool),
                     lam=weights, penalised=np.zeros(4, bool), prior=u0,
                     options=SolverOptions(step_tol=1e-14))

    sol, ev = estimate(fit, lambda u: (A @ u - b, A), u0, u0, np.ones(4, bool), (None,) * 4)
    assert ev.classes == () and np.isfinite(ev.noise_mm)
    assert np.abs(sol.u - np.linalg.lstsq(A, b, rcond=None)[0]).max() < 1e-9


# ------------------------------------------------------------------------- plan
def test_plan_home_not_finite_is_refused(tmp_path, capsys):
    line = _refused(["plan", "ec66", "--poses", "20", "--out", str(tmp_path / "plan.csv"),
                     "--in-cube", "0.4", "0", "0.25", "0.02", "--home", "0", "0", "0", "0",
                     "0", "nan"], tmp_path, capsys)
    assert "--home must be a finite number" in line


def test_plan_pivot_not_finite_is_refused(tmp_path, capsys):
    line = _refused(["plan", "ec66", "--poses", "20", "--out", str(tmp_path / "plan.csv"),
                     "--random", "200", "--kind", "distance", "--pivot", "0", "0", "nan"],
                    tmp_path, capsys)
    assert "--pivot must be a finite number" in line


@pytest.mark.parametrize("edit, said", [
    (lambda t: re.sub(r'(<joint name="joint_3".*?<origin [^>]*/>)', r'\1<origin xyz="0 0 0"/>',
                      t, count=1, flags=re.S),
     ":56:47: joint 'joint_3' has a second <origin>: a URDF joint has at most one"),
    (lambda t: re.sub(r'(<joint name="joint_3".*?<child link=")[^"]*', r'\1link_2', t, count=1,
                      flags=re.S),
     ":54:5: link 'link_2' is the child of two joints ('joint_2' and 'joint_3'): a URDF link "
     "hangs from one joint (a tree)")])
def test_a_joint_of_two_origins_or_a_link_of_two_parents_is_refused_at_reading(
        made, tmp_path, capsys, edit, said):
    """A joint with two <origin> elements was taken by urdfdom (the first) and refused only
    when the corrected URDF was written, as "please report this" (the audit a22); a link
    that is the child of two joints got urdfdom's "Model does not have any body named
    link_2". Both are refused as the URDF is read, naming the line, joints and link."""
    from kincal.robot import Robot

    (tmp_path / "r.urdf").write_text(edit(Robot.load("ec66").urdf_text))
    line = _refused(["calibrate", str(tmp_path / "r.urdf"), str(made / "point.csv"), "--tip",
                     "flange", "--out", str(tmp_path / "c.urdf")], tmp_path, capsys)
    assert line.startswith(f"kincal: error: {tmp_path / 'r.urdf'}{said}"), line


@pytest.mark.parametrize("where, value, said", [
    ("axis", '<axis xyz="1e200 0 1e200"/>', "axis xyz='1e200 0 1e200' is too long to normalise"),
    ("origin", '<origin xyz="1e160 0 0" rpy="0 0 0"/>',
     "origin xyz='1e160 0 0' lies more than 1e+06 m from its parent link")])
def test_urdf_numbers_whose_squares_overflow_are_refused(made, tmp_path, capsys, where, value,
                                                         said):
    """An axis or an origin beyond 1e154 made the kinematics overflow into NaN: a traceback
    (numpy's LinAlgError 'SVD did not converge') instead of one line (the audit a22)."""
    import re

    from kincal.robot import Robot

    text = Robot.load("ec66").urdf_text
    head, tail = text.split('<joint name="joint_4"', 1)
    tail = re.sub(rf"<{where} [^>]*/>", value, tail, count=1)
    (tmp_path / "r.urdf").write_text(head + '<joint name="joint_4"' + tail)
    line = _refused(["calibrate", str(tmp_path / "r.urdf"), str(made / "point.csv"), "--tip",
                     "flange", "--out", str(tmp_path / "c.urdf")], tmp_path, capsys)
    assert "r.urdf:" in line and "joint 'joint_4': " + said in line
