"""Output folders appear with the first file the one writer writes into them, never before
the work: a run that fails leaves no empty folder behind, and a folder the user had stays
as it was; a file the user had is never replaced. (kincal fleet's own case is in
tests/test_fleet_engine.py.)"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from kincal.errors import ExportError
from kincal.experiments import paper_report
from kincal.export import safe_write
from kincal.export.safe_write import missing_folders, write_all


def _no_space(monkeypatch):
    """Every staged file fails as on a full disk."""
    def full(target, data, path):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(safe_write, "_stage", full)


def test_missing_folders_are_the_missing_chain_outermost_first(tmp_path):
    (tmp_path / "a").mkdir()
    assert missing_folders(tmp_path / "a" / "b" / "c") == [
        (tmp_path / "a" / "b").resolve(), (tmp_path / "a" / "b" / "c").resolve()]
    assert missing_folders(tmp_path / "a") == []


def test_nested_new_folders_come_with_the_files_and_go_with_a_failure(tmp_path, monkeypatch):
    out = tmp_path / "x" / "y" / "z"
    assert write_all([(out / "f.txt", "f")], dirs=missing_folders(out)) == [
        (out / "f.txt").resolve()]
    assert (out / "f.txt").read_text() == "f"
    _no_space(monkeypatch)
    again = tmp_path / "p" / "q"
    with pytest.raises(ExportError, match="No space left"):
        write_all([(again / "f.txt", "f")], dirs=missing_folders(again))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x"]  # no p/ left behind


def test_a_folder_made_meanwhile_is_used_and_not_removed(tmp_path, monkeypatch):
    """Units of a fleet write into one new folder at once: the writer that finds it made
    by another one writes into it, and its own failure does not remove it."""
    real_mkdir = Path.mkdir
    shared = (tmp_path / "D").resolve()

    def raced(self, *args, **kwargs):
        if self == shared:
            os.mkdir(self)  # the other unit is quicker
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", raced)
    write_all([(shared / "u1" / "f.txt", "u1")], dirs=[shared, shared / "u1"])
    assert (shared / "u1" / "f.txt").read_text() == "u1"
    shared = (tmp_path / "E").resolve()  # the next one's folder, made meanwhile too
    _no_space(monkeypatch)
    with pytest.raises(ExportError, match="No space left"):
        write_all([(shared / "u2" / "f.txt", "u2")], dirs=[shared, shared / "u2"])
    assert shared.is_dir() and not any(shared.iterdir())  # the other's folder stays


def test_a_failed_paper_report_leaves_no_parent_folders(tmp_path, monkeypatch):
    """write_report made out_dir's parents before writing; now the writer makes them with
    the files and removes them when the writing fails."""
    class Result:
        def as_dict(self):
            return {}

    monkeypatch.setattr(paper_report, "tables", lambda results: "| table |\n")
    monkeypatch.setattr(paper_report, "figures", lambda result, fields: [
        (name, b"\x89PNG") for name in paper_report.PLOT_FILES])
    _no_space(monkeypatch)
    with pytest.raises(ExportError, match="No space left"):
        paper_report.write_report([Result()], tmp_path / "a" / "b" / "report")
    assert list(tmp_path.iterdir()) == []


def test_simulated_fleet_files_go_through_the_writer(tmp_path):
    """FleetModel.tracker_files wrote with Path.write_text, replacing a file of the same
    name; through the one writer it refuses and writes none of the units."""
    import numpy as np

    from kincal.fleet.simulated import FleetModel
    from kincal.robot import Robot

    fm = FleetModel.of(Robot.load("ec66", tip="flange"), 0)
    (tmp_path / "u02.csv").write_text("the user's")
    with pytest.raises(ExportError, match="u02.csv: already exists"):
        fm.tracker_files(tmp_path, 3, np.random.default_rng(0), n=8)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["u02.csv"]
    assert (tmp_path / "u02.csv").read_text() == "the user's"
    files = fm.tracker_files(tmp_path, 1, np.random.default_rng(0), n=8)
    assert [Path(f).name for f in files] == ["u01.csv"]
    assert Path(files[0]).read_text().startswith("# made by kincal")


@pytest.mark.parametrize("existed", [False, True])
def test_fleet_interrupted_before_any_unit_leaves_no_folder_it_made(tmp_path, monkeypatch,
                                                                    capsys, existed):
    """Ctrl-C while the first unit is being written (its staging folder made, nothing
    finished): the folder the run made goes again, a folder the user had stays."""
    pytest.importorskip("distributed")
    import kincal.fleet as fleet
    from kincal.cli import main
    from kincal.fleet.unit import STAGING

    data, data2 = tmp_path / "u1.csv", tmp_path / "u2.csv"  # two units (one twice: refused)
    for seed, path in (("1", data), ("2", data2)):
        assert main(["simulate", "ec66", "--poses", "12", "--seed", seed, "--out", str(path)]) == 0
    out = tmp_path / "D"
    if existed:
        out.mkdir()

    def interrupted(robot, jobs, *args, **kwargs):
        stage = Path(jobs[0].out_dir) / f"{STAGING}{jobs[0].name}"
        stage.mkdir(parents=True)  # as the writer makes them for the first unit
        (stage / "corrected.urdf").write_text("<robot/>")
        raise KeyboardInterrupt

    monkeypatch.setattr(fleet, "calibrate_fleet", interrupted)
    capsys.readouterr()
    assert main(["fleet", "ec66", str(data), str(data2), "--tip", "flange",
                 "--out-dir", str(out)]) == 130
    assert "after 0 of the 2 unit calibrations: nothing was written" in capsys.readouterr().err
    assert out.is_dir() is existed
    if existed:
        assert list(out.iterdir()) == []


def test_an_interrupted_fleet_names_the_earlier_run_s_files_it_leaves(tmp_path, monkeypatch,
                                                                   capsys):
    """Ctrl-C after unit u1 finished, into a folder an earlier run filled (--overwrite): u1
    is put in place, u2's half-written staging goes, and the line names what is the
    earlier run's (its FLEET.json and u2's folder), which are left as they were."""
    pytest.importorskip("distributed")
    import kincal.fleet as fleet
    from kincal.cli import main
    from kincal.fleet.unit import STAGING, UnitOutcome

    data, data2 = tmp_path / "u1.csv", tmp_path / "u2.csv"
    for seed, path in (("1", data), ("2", data2)):
        assert main(["simulate", "ec66", "--poses", "12", "--seed", seed, "--out", str(path)]) == 0
    out = tmp_path / "D"
    for unit in ("u1", "u2"):
        (out / unit).mkdir(parents=True)
        for name in ("corrected.urdf", "FRAMES.json", "REPORT.json"):
            (out / unit / name).write_text("earlier")
    (out / "FLEET.json").write_text("earlier")

    def interrupted(robot, jobs, workers, scheduler, rounds, progress, *args, **kwargs):
        for job, text in zip(jobs, ("new", "half")):
            stage = Path(job.out_dir) / f"{STAGING}{job.name}"
            stage.mkdir(parents=True)
            (stage / "corrected.urdf").write_text(text)
        progress(1, 2, UnitOutcome(jobs[0].name, jobs[0].source, "calibrated"))
        raise KeyboardInterrupt

    monkeypatch.setattr(fleet, "calibrate_fleet", interrupted)
    capsys.readouterr()
    assert main(["fleet", "ec66", str(data), str(data2), "--tip", "flange", "--out-dir",
                 str(out), "--overwrite", "--quiet"]) == 130
    err = capsys.readouterr().err
    assert "the 1 unit(s) finished are in place" in err and "(u1)" in err, err
    assert "an earlier run's FLEET.json, u2 in" in err, err
    assert (out / "u1" / "corrected.urdf").read_text() == "new"
    assert (out / "u2" / "corrected.urdf").read_text() == "earlier"
    assert (out / "FLEET.json").read_text() == "earlier"
    assert sorted(p.name for p in out.iterdir()) == ["FLEET.json", "u1", "u2"]


def test_a_fleet_units_failure_leaves_the_shared_folder_to_the_unit_about_to_write(
        tmp_path, monkeypatch):
    """Two units of a fleet, the fleet's folder not there yet: unit A makes it with its
    first file and then fails (a full disk, injected); unit B has checked its outputs and is
    about to make its staging folder in it. A's rollback removed the folder it had made,
    and B failed ("No such file or directory") although nothing was wrong with B; now the
    fleet's folder is shared (kincal.export.safe_write.write_all's shared_dirs): A's
    failure removes only A's staging folder, B writes. Deterministic: each step waits for
    the other's."""
    import functools
    import threading
    import warnings

    from kincal.errors import KincalWarning
    from kincal.fleet.folders import commit_units
    from kincal.fleet.unit import STAGING, UnitJob, calibrate_unit
    from kincal.identification.options import CalibrationOptions
    import numpy as np

    from kincal.fleet.simulated import FleetModel
    from kincal.robot import Robot

    fm = FleetModel.of(Robot.load("ec66", tip="flange"), 0)
    rng = np.random.default_rng(1)
    data = fm.rtest(fm.unit(rng), rng, n=30)
    out = tmp_path / "D"
    a_made, b_checked, a_done = threading.Event(), threading.Event(), threading.Event()
    real_stage, real_mkdir = safe_write._stage, Path.mkdir

    def stage(target, content, path):
        if f"{STAGING}A" in str(target):  # A: its folders are made; wait for B, then fail
            a_made.set()
            assert b_checked.wait(60)
            raise OSError(28, "No space left on device")
        return real_stage(target, content, path)

    def mkdir(self, *args, **kwargs):
        if self.name == f"{STAGING}B":  # B checked, its staging folder next: A fails first
            b_checked.set()
            assert a_done.wait(60)
        return real_mkdir(self, *args, **kwargs)

    monkeypatch.setattr(safe_write, "_stage", stage)
    monkeypatch.setattr(Path, "mkdir", mkdir)

    def job(name):
        return UnitJob(name, f"<{name}>", functools.partial(Robot.load, "ec66", tip="flange"),
                       functools.partial(lambda d, r: [d], data),
                       CalibrationOptions(tool_guess=(0, 0, 0.11)),
                       str(out), accept_implausible=True)

    got = {}

    def run_a():
        try:
            got["A"] = calibrate_unit(job("A"))
        finally:
            a_done.set()

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        thread = threading.Thread(target=run_a)
        thread.start()
        assert a_made.wait(120)
        got["B"] = calibrate_unit(job("B"))
        thread.join(60)
    assert got["A"].status == "failed" and "No space left" in got["A"].message
    assert got["B"].status == "calibrated", got["B"].message
    # B staged, waiting for the fleet's outcome; no staging folder of A's left
    assert sorted(p.name for p in out.iterdir()) == [f"{STAGING}B"]
    commit_units(out, ["B"], overwrite=False).done()
    assert sorted(p.name for p in out.iterdir()) == ["B"]
    assert sorted(p.name for p in (out / "B").iterdir()) == [
        "FRAMES.json", "REPORT.json", "corrected.urdf"]


def test_a_fleet_unit_that_cannot_take_its_name_keeps_the_earlier_files(tmp_path, monkeypatch):
    """--overwrite: the earlier DIR/<unit> is moved aside, the new one renamed in. When that
    rename failed, the earlier files stayed hidden as DIR/.partial-old-<unit> (which the
    command's clean-up of staging folders then deletes) and the unit came back as an
    internal error; now they are back under their name, every unit put in place before is
    taken out again (the fleet's units are put in place together, kincal.fleet.folders),
    and one line says so."""
    import functools
    import warnings

    import numpy as np

    from kincal.errors import ExportError, KincalWarning
    from kincal.fleet import folders
    from kincal.fleet.folders import commit_units, discard_staged
    from kincal.fleet.simulated import FleetModel
    from kincal.fleet.unit import STAGING, UnitJob, calibrate_unit
    from kincal.identification.options import CalibrationOptions
    from kincal.robot import Robot

    fm = FleetModel.of(Robot.load("ec66", tip="flange"), 0)
    rng = np.random.default_rng(1)
    data = fm.rtest(fm.unit(rng), rng, n=30)
    out = tmp_path / "D"

    def job(name):
        return UnitJob(name, f"<{name}>", functools.partial(Robot.load, "ec66", tip="flange"),
                       functools.partial(lambda d, r: [d], data),
                       CalibrationOptions(tool_guess=(0, 0, 0.11)), str(out), overwrite=True)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", KincalWarning)
        for name in ("u0", "u1"):
            assert calibrate_unit(job(name)).status == "calibrated"
        commit_units(out, ["u0", "u1"], overwrite=True).done()
        before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
        for name in ("u0", "u1"):
            assert calibrate_unit(job(name)).status == "calibrated"  # staged again
        real = os.replace

        def replace(src, dst):
            if Path(src).name == f"{STAGING}u1":
                raise OSError(28, "No space left on device")
            return real(src, dst)

        monkeypatch.setattr(folders.os, "replace", replace)
        with pytest.raises(ExportError, match="No space left.*the earlier ones are kept"):
            commit_units(out, ["u0", "u1"], overwrite=True)
    discard_staged(out)
    assert sorted(p.name for p in out.iterdir()) == ["u0", "u1"]  # u0 taken out again too
    assert {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()} == before
