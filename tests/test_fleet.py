"""Fleets: the prior in the penalty (API and --prior), FLEET.json's checks, and kincal fleet
on a local Dask cluster (units all-or-none, a bad unit reported, the prior written)."""

from __future__ import annotations

import json
import re
import warnings

import numpy as np
import pytest
import scipy.linalg

from kincal.cli import main
from kincal.errors import KincalWarning, OptionError, PriorError
from kincal.fleet.simulated import FleetModel
from kincal.frames_file import chain_hash
from kincal.identification.options import CalibrationOptions
from kincal.identification.prior import FleetPrior, shrink_to_diagonal
from kincal.identification.problem import CalibrationProblem
from kincal.identification.solver import solve
from kincal.robot import Robot

distributed = pytest.importorskip(
    "distributed", reason='kincal fleet needs Dask distributed: pip install "kincal[fleet]"')


@pytest.fixture(scope="module")
def fleet_files(tmp_path_factory):
    """4 tracker units (u01..u04), a bad file, and a new unit by R-test (new.csv)."""
    d = tmp_path_factory.mktemp("fleet")
    robot = Robot.load("ec66", tip="flange")
    fm = FleetModel.of(robot, 0)
    rng = np.random.default_rng(1)
    fm.tracker_files(d, 4, rng, n=30)
    (d / "new.csv").write_text(fm.rtest(fm.unit(rng), rng, n=30).to_csv_text())
    (d / "bad.csv").write_text("joint_1,x\n1,2\n")
    return d


@pytest.fixture(scope="module")
def fleet_dir(fleet_files):
    out = fleet_files / "D"
    files = [str(fleet_files / f"u{u:02d}.csv") for u in range(1, 5)] + [
        str(fleet_files / "bad.csv")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(["fleet", "ec66", *files, "--tip", "flange", "--tool-offset", "0", "0",
                     "0.045", "--out-dir", str(out), "--workers", "2", "--quiet"]) == 0
    return out


def test_fleet_writes_units_prior_and_summary(fleet_dir):
    for u in ("u01", "u02", "u03", "u04"):
        assert sorted(p.name for p in (fleet_dir / u).iterdir()) == [
            "FRAMES.json", "REPORT.json", "corrected.urdf"]
    assert not (fleet_dir / "bad").exists()  # a bad unit writes nothing ...
    assert not list(fleet_dir.glob(".partial-*"))
    summary = json.loads((fleet_dir / "FLEET_SUMMARY.json").read_text())
    status = {u["name"]: u["status"] for u in summary["units"]}
    assert status == {"u01": "calibrated", "u02": "calibrated", "u03": "calibrated",
                      "u04": "calibrated", "bad": "failed"}  # ... and is reported
    assert "missing column" in [u for u in summary["units"] if u["name"] == "bad"][0]["message"]
    prior = FleetPrior.read(fleet_dir / "FLEET.json")
    assert prior.n_units == 4 and prior.model == "complete"
    assert prior.covariance.shape == (len(prior.names),) * 2
    assert "<img" in (fleet_dir / "fleet.html").read_text()
    # the tool is not in the prior: only the kinematic parameters
    assert not any(n.startswith(("tool", "base")) for n in prior.names)


def test_calibrate_with_prior_and_another_tool(fleet_files, fleet_dir, capsys):
    out = fleet_files / "new.urdf"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(["calibrate", "ec66", str(fleet_files / "new.csv"), "--tip", "flange",
                     "--tool-offset", "0", "0", "0.11", "--prior", str(fleet_dir / "FLEET.json"),
                     "--out", str(out)]) == 0
    assert out.exists()
    assert "fleet" in capsys.readouterr().out  # the evidence's fleet class


@pytest.mark.parametrize("extra, words", [
    (["--model", "mdh"], "error model complete"),
    (["--tip", "link_6"], "another robot or chain"),
    (["--method", "ls"], "method l2"),
    (["--lambda", "0"], "lambda 0 (--lambda 0) switches off"),  # was taken, the prior ignored
])
def test_a_prior_of_another_chain_or_model_is_refused(fleet_files, fleet_dir, capsys, extra,
                                                      words):
    argv = ["calibrate", "ec66", str(fleet_files / "new.csv"), "--tip", "flange",
            "--prior", str(fleet_dir / "FLEET.json"), "--out", str(fleet_files / "x.urdf")]
    i = argv.index("--tip")
    if extra[0] == "--tip":
        argv[i + 1] = extra[1]
    else:
        argv += extra
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("kincal: error:") and words in err[-1]
    assert not (fleet_files / "x.urdf").exists()


@pytest.mark.parametrize("robot", ["longer", "corrected"])
def test_a_prior_of_a_robot_of_another_design_is_refused(fleet_files, fleet_dir, capsys, robot):
    """The chain hash leaves the link lengths out (FRAMES.json must fit a corrected URDF),
    so a prior learned on one design was taken by another with the same joints and axes
    (a UR5e's by a UR10e, 0.5 mm on one link here) and by a unit's corrected URDF, whose
    nominal already holds that unit's deviation: the fleet mean was added on top. The
    prior records its nominal values and is refused with another's, naming the largest."""
    if robot == "longer":
        path = fleet_files / "ec66-longer.urdf"
        text = _ec66_text()
        assert text.count('xyz="0.398 0 0.098"') == 1
        path.write_text(text.replace('xyz="0.398 0 0.098"', 'xyz="0.398 0 0.0985"'))
    else:
        path = fleet_dir / "u01" / "corrected.urdf"
    out = fleet_files / f"y-{robot}.urdf"
    argv = ["calibrate", str(path), str(fleet_files / "new.csv"), "--tip", "flange",
            "--tool-offset", "0", "0", "0.11", "--prior", str(fleet_dir / "FLEET.json"),
            "--out", str(out)]
    assert main(argv) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("kincal: error: the fleet prior was learned on a robot of "
                              "another design"), err
    if robot == "longer":
        assert "(the most joint_4.d: 98.0000 mm there, 98.5000 mm here)" in err[-1]
    assert not out.exists()
    # the design the fleet was learned on is taken, as written by kincal fleet
    d = json.loads((fleet_dir / "FLEET.json").read_text())
    assert all("nominal" in q for q in d["parameters"]) and d["version"] == 2


def test_a_prior_of_version_1_is_refused(tmp_path, fleet_dir):
    """Version 1 recorded no nominal values: it cannot be checked against the design."""
    d = json.loads((fleet_dir / "FLEET.json").read_text())
    d["version"] = 1
    for q in d["parameters"]:
        del q["nominal"]
    (tmp_path / "F.json").write_text(json.dumps(d))
    with pytest.raises(PriorError, match="version 1, which does not record the nominal"):
        FleetPrior.read(tmp_path / "F.json")


def test_a_malformed_prior_is_refused(tmp_path, fleet_dir):
    d = json.loads((fleet_dir / "FLEET.json").read_text())
    d["covariance"] = d["covariance"][:-1]
    bad = tmp_path / "F.json"
    bad.write_text(json.dumps(d))
    with pytest.raises(PriorError, match="covariance"):
        FleetPrior.read(bad)
    with pytest.raises(PriorError, match="not a fleet prior"):
        (tmp_path / "G.json").write_text("[]")
        FleetPrior.read(tmp_path / "G.json")
    # a NaN is named as what it is, where it is (it said "got shape (k, k)", the right shape)
    for where in ("covariance", "mean"):
        d = json.loads((fleet_dir / "FLEET.json").read_text())
        words = (f"mean deviation of {d['parameters'][1]['name']} is not a finite number"
                 if where == "mean" else "got a NaN or infinity")
        if where == "covariance":
            d["covariance"][1][1] = float("nan")
        else:
            d["parameters"][1]["mean"] = float("nan")
        bad.write_text(json.dumps(d))
        with pytest.raises(PriorError, match=words):
            FleetPrior.read(bad)


def test_prior_option_needs_a_fleet_prior():
    with pytest.raises(OptionError, match="FleetPrior"):
        CalibrationOptions(prior="FLEET.json").validated()


def test_matrix_penalty_matches_the_closed_form():
    """A linear problem: (J^T J + Lam) d = J^T y + Lam m, the solver's answer with a
    matrix penalty (a fleet prior's precision) centred on m."""
    rng = np.random.default_rng(3)
    J = rng.normal(size=(12, 4))
    y = rng.normal(size=12)
    A = rng.normal(size=(4, 4))
    Lam = A @ A.T + 0.1 * np.eye(4)
    m = rng.normal(size=4)
    residual = lambda u, jac: (J @ u - y, J if jac else None)  # noqa: E731
    sol = solve(residual, np.zeros(4), np.ones(4, bool), lam=Lam,
                penalised=np.ones(4, bool), prior=m)
    expected = np.linalg.solve(J.T @ J + Lam, J.T @ y + Lam @ m)
    assert np.allclose(sol.u, expected, atol=1e-9)


def test_shrinkage_keeps_variances_and_shrinks_correlations():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(6, 5))
    S, lam = shrink_to_diagonal(X)
    assert np.allclose(np.diag(S), X.var(axis=0, ddof=1))
    assert 0 <= lam <= 1
    C = np.cov(X.T)
    off = ~np.eye(5, dtype=bool)
    assert np.allclose(S[off], (1 - lam) * C[off])


def test_prior_pulls_toward_the_fleet_mean_where_data_are_blind():
    """With a prior whose mean is a planted deviation and a tight covariance, the R-test
    fit (lambda 1: the prior as given, 0.01 mm per a) ends near the fleet mean on those
    parameters; without it, elsewhere."""
    robot = Robot.load("ec66", tip="flange")
    fm = FleetModel.of(robot, 2)
    rng = np.random.default_rng(2)
    table = fm.model.nominal + fm.systematic
    data = fm.rtest(table, rng, n=30)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        p = CalibrationProblem(robot, data, CalibrationOptions(tool_guess=(0, 0, 0.11)))
        plain = p.solve()
        k = p.layout.n_kinematic
        units = np.array([plain.x[:k] - plain.x_nominal[:k]] * 2)
        mean = np.zeros(k)
        moved = np.array([p.layout.kinematic_names[i].endswith(".a") for i in range(k)])
        mean[moved] = 2e-4  # 0.2 mm on every a
        prior = FleetPrior.estimate(robot, p.model_name, p.layout.kinematic_names,
                                    p.layout.is_length[:k], p.x_nominal[:k], units, ["a", "b"])
        prior = FleetPrior(prior.robot, prior.robot_hash, prior.model, prior.names,
                           prior.is_length, prior.nominal, mean,
                           np.diag(np.where(moved, 1e-10, 0.0)), prior.units, 1.0)
        fitted = CalibrationProblem(robot, data, CalibrationOptions(
            tool_guess=(0, 0, 0.11), prior=prior, lam=1.0)).solve()
    dev = fitted.x[:k] - fitted.x_nominal[:k]
    assert np.allclose(dev[moved], 2e-4, atol=5e-5)
    assert np.max(np.abs((plain.x[:k] - plain.x_nominal[:k])[moved] - 2e-4)) > 5e-5


def test_a_parameter_that_never_moved_in_the_fleet_is_held_at_the_fleet_mean():
    """A kinematic parameter with no fleet variance (it never moved in any unit: redundant
    in the error model, or fixed there) is held at the fleet mean, as docs/fleet.md says.
    It was fitted instead whenever the new unit's data identified it (at the fleet mean
    the parallel axes of joints 2-4 are no longer exactly parallel, so joint_2.d and
    joint_3.d were "identified" by an R-test), with a pull toward nominal of its own."""
    robot = Robot.load("ec66", tip="flange")
    fm = FleetModel.of(robot, 0)
    rng = np.random.default_rng(3)
    data = fm.tracker(fm.unit(rng), rng, n=40)  # wide: joint_4.a is well identified
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        p = CalibrationProblem(robot, data, CalibrationOptions(tool_guess=(0, 0, 0.045)))
        k = p.layout.n_kinematic
        names = p.layout.kinematic_names
        i = names.index("joint_4.a")
        assert "joint_4.a" in p.analyze().kept
        sd = np.where(np.asarray(p.layout.is_length[:k]), 1e-4, 1e-4 * np.pi / 180)
        sd[i] = 0.0  # never moved in the fleet
        mean = np.zeros(k)
        mean[i] = 3e-4
        prior = FleetPrior(robot.model_name, chain_hash(robot), p.model_name, tuple(names),
                           tuple(bool(v) for v in p.layout.is_length[:k]), p.x_nominal[:k],
                           mean, np.diag(sd ** 2), ("a", "b"), 1.0)
        for lam in ("evidence", 0.0025):
            fitted = CalibrationProblem(robot, data, CalibrationOptions(
                tool_guess=(0, 0, 0.045), prior=prior, lam=lam)).solve()
            assert fitted.x[i] - fitted.x_nominal[i] == pytest.approx(3e-4, abs=1e-12)


def test_hierarchical_rounds_write_once_and_learn_a_hierarchical_prior(fleet_files, capsys):
    out = fleet_files / "H"
    files = [str(fleet_files / f"u{u:02d}.csv") for u in range(1, 4)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(["fleet", "ec66", *files, "--tip", "flange", "--tool-offset", "0", "0",
                     "0.045", "--out-dir", str(out), "--hierarchical", "1"]) == 0
    captured = capsys.readouterr()
    assert "unit 6/6" in captured.err  # progress counts the units of both rounds
    assert "1 rounds of the hierarchical fit" in captured.out
    prior = FleetPrior.read(out / "FLEET.json")
    assert prior.method == "hierarchical" and prior.n_units == 3
    assert sorted(p.name for p in out.iterdir() if p.is_dir()) == ["u01", "u02", "u03"]


def test_existing_unit_folders_need_overwrite(fleet_files, fleet_dir, capsys):
    assert main(["fleet", "ec66", str(fleet_files / "u01.csv"), str(fleet_files / "u02.csv"),
                 "--tip", "flange", "--out-dir", str(fleet_dir)]) == 1
    assert "kincal: error:" in capsys.readouterr().err


def test_overwrite_replaces_no_unit_folder_holding_other_files(fleet_files, tmp_path, capsys):
    """--overwrite replaces a unit's folder whole: a note the user put there, or a data
    file read from there (DIR/a/x.csv beside a unit named a), was deleted with it. A unit
    folder holding more than a unit's three files is refused before the work."""
    import shutil

    out = tmp_path / "D"
    (out / "u01").mkdir(parents=True)
    (out / "u01" / "notes.txt").write_text("the user's")
    shutil.copy(fleet_files / "u02.csv", out / "u01" / "x.csv")
    for data in ([fleet_files / "u01.csv"], [out / "u01" / "x.csv", fleet_files / "u01.csv"]):
        capsys.readouterr()
        assert main(["fleet", "ec66", *map(str, data), str(fleet_files / "u02.csv"), "--tip",
                     "flange", "--out-dir", str(out), "--overwrite"]) == 1
        err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
        assert len(err) == 1 and "holds files a fleet unit does not write (notes.txt, x.csv)" \
            in err[0], err
    assert sorted(p.name for p in (out / "u01").iterdir()) == ["notes.txt", "x.csv"]
    assert sorted(p.name for p in out.iterdir()) == ["u01"]
    # a unit's folder holding the robot this run starts from (an earlier unit's URDF)
    for name in ("notes.txt", "x.csv"):
        (out / "u01" / name).unlink()
    (out / "u01" / "corrected.urdf").write_text(_ec66_text())
    capsys.readouterr()
    assert main(["fleet", str(out / "u01" / "corrected.urdf"), str(fleet_files / "u01.csv"),
                 str(fleet_files / "u02.csv"), "--tip", "flange", "--out-dir", str(out),
                 "--overwrite"]) == 1
    assert "(corrected.urdf)" in capsys.readouterr().err
    assert (out / "u01" / "corrected.urdf").read_text() == _ec66_text()


def _ec66_text() -> str:
    from conftest import EC66

    return EC66.read_text()


def _tree(folder) -> dict:
    """Every file and folder under ``folder``: bytes and modification times."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None,
                                         p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*"))}


def test_a_fleet_that_fails_writes_nothing_and_replaces_nothing(fleet_files, tmp_path, capsys):
    """Fewer than 2 units calibrated: the fleet fails (exit 1, no prior). It still wrote
    FLEET_SUMMARY.json and fleet.html, replaced them under --overwrite, and put the one
    calibrated unit's files in place (over the earlier run's): result files a pipeline could
    take for this failed run's. Now nothing is written or replaced, and the one error line
    names each unit's outcome."""
    out = tmp_path / "D"
    good = [str(fleet_files / "u01.csv"), str(fleet_files / "u02.csv")]
    argv = ["fleet", "ec66", "--tip", "flange", "--tool-offset", "0", "0", "0.045", "--quiet",
            "--out-dir", str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main([*argv, *good]) == 0
        before = _tree(out)
        assert {"FLEET.json", "FLEET_SUMMARY.json", "fleet.html", "u01/corrected.urdf"} <= set(before)
        capsys.readouterr()
        assert main([*argv, good[0], str(fleet_files / "bad.csv"), "--overwrite"]) == 1
        err = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
        assert _tree(out) == before  # u01 calibrated again, but not put in place
        (line,) = err
        assert line.startswith("kincal: error: fewer than 2 of the 2 units were calibrated")
        assert "u01: calibrated" in line and "bad: failed (" in line and "missing" in line, line
        assert "FLEET.json is an earlier run's, left as it was" in line, line
        fresh = tmp_path / "E"  # a folder the run would have made: not made
        capsys.readouterr()
        assert main([*argv[:-1], str(fresh), good[0], str(fleet_files / "bad.csv")]) == 1
    assert not fresh.exists()


def test_an_empty_out_dir_is_refused_not_the_current_folder(fleet_files, tmp_path, capsys,
                                                             monkeypatch):
    """--out-dir "" (a script's unset variable) wrote every unit, the summary and the prior
    into the current folder (Path("") is "."), where calibrate --out "" is refused."""
    monkeypatch.chdir(tmp_path)
    files = [str(fleet_files / f"u0{u}.csv") for u in (1, 2)]
    assert main(["fleet", "ec66", *files, "--tip", "flange", "--out-dir", ""]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["kincal: error: an output folder must be a non-empty str or Path, got ''"]
    assert list(tmp_path.iterdir()) == []


def test_unit_names_are_unique_folders():
    """x/a.csv, y/a.csv and a-2.csv made the units a-1, a-2, a-2: the second a-2 found the
    first one's folder (failed, or with --overwrite replaced it), and the summary listed
    one outcome twice, the other lost. Names equal but for case are one folder on a
    case-insensitive file system; the fleet's own file names are refused."""
    from kincal.cli.fleet import unit_names

    assert unit_names(["x/a.csv", "y/a.csv", "a-2.csv", "b.csv"]) == ["a-1", "a-2-2", "a-2",
                                                                       "b"]
    assert unit_names(["u1.csv", "u2.csv"]) == ["u1", "u2"]
    assert unit_names(["x/a.csv", "y/a.csv", "a-2.csv", "a-2-2.csv"]) == [
        "a-1", "a-2-3", "a-2", "a-2-2"]
    assert unit_names(["U1.csv", "x/u1.csv"]) == ["U1-1", "u1-2"]
    for bad in ("FLEET.json.csv", "fleet.html.csv", ".partial-u1.csv"):
        with pytest.raises(OptionError, match="rename the data file"):
            unit_names([bad, "u2.csv"])


def test_hierarchical_e_step_keeps_the_prior_as_it_is_and_its_width_where_blind(fleet_dir):
    """A round of the hierarchical fit: the prior's scale held at 1 (the evidence estimates
    only the noise), and the unit's posterior covariance: narrower than the prior where the
    R-test sees, as wide where it is blind (not ~0, as the estimator's sandwich would be)."""
    import functools

    from kincal.fleet import UnitJob, calibrate_unit

    prior = FleetPrior.read(fleet_dir / "FLEET.json")
    robot = Robot.load("ec66", tip="flange")
    fm = FleetModel.of(robot, 0)
    rng = np.random.default_rng(5)
    data = fm.rtest(fm.unit(rng), rng, n=30)
    opts = CalibrationOptions(tool_guess=(0, 0, 0.11), prior=prior, lam="evidence",
                              prior_scale=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        result = CalibrationProblem(robot, data, opts).solve()
        unit = calibrate_unit(UnitJob("n", "<R-test>", functools.partial(Robot.load, "ec66",
                                                                         tip="flange"),
                                      functools.partial(lambda d, r: [d], data), opts, None))
    assert result.evidence.scale_of("fleet") == 1.0 and "fleet 1 x" in result.evidence.line()
    assert unit.status == "calibrated"
    v = np.diag(prior.covariance) > 0
    P = prior.covariance[np.ix_(v, v)]
    # the posterior against the prior, direction by direction: eigenvalues of P^-1 C
    ratio = scipy.linalg.eigh(unit.covariance[np.ix_(v, v)], P, eigvals_only=True)
    assert np.all(ratio <= 1 + 1e-6)
    assert ratio.min() < 0.9 and ratio.max() > 0.99  # seen somewhere, blind elsewhere
    k = result.layout.n_kinematic
    sandwich = scipy.linalg.eigh(result.covariance[:k, :k][np.ix_(v, v)], P, eigvals_only=True)
    assert sandwich.max() < 0.5  # the sandwich loses the blind directions


def test_prior_scale_needs_a_prior_and_evidence():
    with pytest.raises(OptionError, match="prior_scale"):
        CalibrationOptions(prior_scale=1.0).validated()


def test_one_units_data_given_twice_is_refused(fleet_files, tmp_path, capsys):
    """The same file twice (or a copy of it) made two units, u01-1 and u01-2, of one unit's
    data, exit 0: a prior whose scatter shrank toward that unit. Refused, nothing written."""
    import shutil

    one = fleet_files / "u01.csv"
    shutil.copy(one, tmp_path / "copy.csv")
    out = tmp_path / "D"
    for twice, says in (([one, one], "u01.csv is given twice"),
                        ([one, fleet_files / "u02.csv", fleet_files / "x" / ".." / "u01.csv"],
                         f"u01.csv is {one}"),
                        ([one, fleet_files / "u02.csv", tmp_path / "copy.csv"],
                         f"copy.csv has the same bytes as {one}")):
        (fleet_files / "x").mkdir(exist_ok=True)
        capsys.readouterr()
        assert main(["fleet", "ec66", *map(str, twice), "--tip", "flange", "--out-dir",
                     str(out)]) == 1
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        assert len(err) == 1 and err[0].startswith("kincal: error:") and says in err[0], err
        assert "one unit's data given twice" in err[0] and not out.exists()


def test_a_fleet_whose_summary_cannot_be_written_takes_its_units_out_again(
        fleet_files, tmp_path, capsys, monkeypatch):
    """The units are put in place just before the summary and the prior are written; if
    those cannot be (a full disk, a closed stdout), the units go out again and the earlier
    ones come back: all of the fleet's files, or none."""
    import kincal.cli.console as console
    from kincal.errors import ExportError

    out = tmp_path / "D"
    argv = ["fleet", "ec66", str(fleet_files / "u01.csv"), str(fleet_files / "u02.csv"),
            "--tip", "flange", "--tool-offset", "0", "0", "0.045", "--quiet", "--out-dir",
            str(out)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(argv) == 0
        before = _tree(out)

        def full(*args, **kwargs):
            assert (out / "u01" / "corrected.urdf").exists()  # the units are in place
            raise ExportError("FLEET_SUMMARY.json: could not write (No space left on device)")

        monkeypatch.setattr(console, "say_and_write", full)
        capsys.readouterr()
        assert main([*argv, "--overwrite"]) == 1
        assert _tree(out) == before
        fresh = tmp_path / "E"
        assert main([*argv[:-1], str(fresh)]) == 1
    assert not fresh.exists()
    assert "No space left" in capsys.readouterr().err


@pytest.mark.parametrize("edit,words", [
    (lambda d: d.update(units="".join(d["units"])), "units must be a list"),
    (lambda d: d["parameters"][0].update(mean=True), "True is not a number"),
    (lambda d: d["parameters"][0].update(mean="0.001"), "'0.001' is not a number"),
    (lambda d: d["parameters"][0].update(nominal=None), "None is not a number"),
    (lambda d: d.update(n_units=d["n_units"] + 1), "n_units"),
])
def test_a_hand_edited_prior_is_read_as_written_or_refused(tmp_path, fleet_dir, edit, words):
    """A FLEET.json edited by hand: the units' names as one string were read as one unit per
    character, a boolean or a quoted number as a mean, a unit count that disagrees with the
    units named went unseen. Each is refused naming it."""
    d = json.loads((fleet_dir / "FLEET.json").read_text())
    edit(d)
    (tmp_path / "F.json").write_text(json.dumps(d))
    with pytest.raises(PriorError, match=re.escape(words)):
        FleetPrior.read(tmp_path / "F.json")


def test_model_auto_takes_the_prior_s_model(fleet_files, tmp_path, capsys):
    """A fleet learned with --model mdh: calibrate --prior with the default --model auto
    was refused ("give --model mdh"), the choice built on the chain's default (complete),
    which the prior does not cover. Auto now takes the prior's model and says why; an
    explicit other model is still refused (above)."""
    out = tmp_path / "D"
    files = [str(fleet_files / f"u{u:02d}.csv") for u in range(1, 4)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        assert main(["fleet", "ec66", *files, "--tip", "flange", "--tool-offset", "0", "0",
                     "0.045", "--model", "mdh", "--out-dir", str(out), "--workers", "1",
                     "--quiet"]) == 0
        assert FleetPrior.read(out / "FLEET.json").model == "mdh"
        capsys.readouterr()
        code = main(["calibrate", "ec66", str(fleet_files / "new.csv"), "--tip", "flange",
                     "--tool-offset", "0", "0", "0.11", "--prior", str(out / "FLEET.json"),
                     "--out", str(tmp_path / "new.urdf"), "--json"])
    got = capsys.readouterr()
    assert code == 0, got.err
    result = json.loads(got.out)
    text = json.dumps(result)
    assert "the fleet prior's model" in text and '"mdh"' in text
    assert (tmp_path / "new.urdf").exists()


def test_the_summary_file_gives_si_beside_mm_and_deg(fleet_dir):
    """FLEET_SUMMARY.json gave each parameter's mean and scatter in mm or deg only (files are
    SI, as REPORT.json does beside its human units): now mean_m / scatter_m (lengths) or
    mean_rad / scatter_rad (angles) too, equal to FLEET.json's."""
    summary = json.loads((fleet_dir / "FLEET_SUMMARY.json").read_text())
    prior = FleetPrior.read(fleet_dir / "FLEET.json")
    rows = summary["parameters"]
    assert [r["name"] for r in rows] == list(prior.names)
    for r, is_len, m, s in zip(rows, prior.is_length, prior.mean, prior.std):
        si, k = ("m", 1e3) if is_len else ("rad", 180.0 / np.pi)
        assert r["unit"] == ("mm" if is_len else "deg")
        assert r[f"mean_{si}"] == pytest.approx(m, rel=1e-12, abs=1e-300)
        assert r[f"scatter_{si}"] == pytest.approx(s, rel=1e-12, abs=1e-300)
        assert r["mean"] == pytest.approx(m * k, rel=1e-12, abs=1e-300)


def test_units_failing_alike_are_named_in_one_clause(fleet_files, tmp_path, capsys):
    """`--fix joint_9.a` (no such parameter) failed every unit with the same reason, and the
    fleet's one error line repeated that reason, with its list of the valid names, once per
    unit (200 units: 200 copies). Units with one outcome and reason are one clause."""
    files = [str(fleet_files / f"u0{u}.csv") for u in (1, 2, 3)]
    assert main(["fleet", "ec66", *files, "--tip", "flange", "--quiet", "--out-dir",
                 str(tmp_path / "D"), "--fix", "joint_9.a"]) == 1
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "Units: u01, u02, u03: failed (unknown parameter 'joint_9.a'." in line, line
    assert line.count("unknown parameter") == 1, line
    assert not (tmp_path / "D").exists()
    from kincal.cli.fleet import _some

    assert _some([f"u{k}" for k in range(8)]) == "u0, u1, u2, u3, u4 and 3 more"
