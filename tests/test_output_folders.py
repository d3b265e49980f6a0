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
