"""The simulated paper experiment, its tables, its plots and the demo.

One run of the small configuration (module fixture) serves the claims, the tables and
the plots; demo() runs once more with a coarse CV grid to check what it writes.
"""

import json
import struct
from dataclasses import replace

import numpy as np
import pytest

from kincal.errors import ExportError
from kincal.experiments.paper_experiment import ExperimentConfig, run
from kincal.experiments.paper_report import (PLOT_FILES, REPORT_FILES, demo, figures, tables,
                                             write_report)
from kincal.export import plots

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path):
    """(width, height) from the IHDR chunk, after checking the PNG signature."""
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path.name} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def result():
    return run(ExperimentConfig.small(seed=0))


def test_l2_generalises_better_than_ls_from_the_small_cube(result):
    ls, l2 = result.method("ls_rtest"), result.method("l2_rtest")
    before, tracker = result.method("before"), result.method("ls_tracker")
    # both fit the 20 mm cube to about the noise level (0.1 mm per axis: mean norm ~0.16)
    assert ls.calibration.mean < before.calibration.mean
    assert abs(l2.calibration.mean - ls.calibration.mean) < 0.02
    # ... but only L2 carries over to the 400 mm cube
    assert l2.validation.mean < 0.8 * ls.validation.mean
    assert l2.validation.mean < 0.7 * before.validation.mean
    assert tracker.validation.mean < l2.validation.mean
    assert 0 < result.lam < 1e3 and result.lam == result.cv.best_lambda
    assert len(l2.validation_errors_mm) == result.config.n_tracker_points == 150
    assert np.isclose(l2.validation_errors_mm.mean(), l2.validation.mean)
    # the planted truth is Table 4's tracker column plus the jitter: theta_o4 = 0.747 deg
    i = result.parameter_names.index("joint_4.theta")
    assert abs(result.true_deviations[i] - 0.747) < 0.1


def test_tables_have_the_papers_rows(result):
    text = tables([result])
    for title in ("**Table 2.**", "**Table 3.**", "**Table 4.**"):
        assert title in text
    v = result.method("l2_rtest").validation
    assert f"| L2 + R-test | 400 mm cube | {v.mean:.3f} | {v.max:.3f} | {v.std:.3f} | " \
           "0.399 / 0.665 / 0.104 |" in text
    for label in ("Before calibration", "LS + R-test", "LS + laser tracker"):
        assert f"| {label} | " in text
    row = next(line for line in text.splitlines() if line.startswith("| joint_4.theta (deg) |"))
    assert row.count("|") == 6  # parameter, three methods, truth
    two = tables([result, result])
    assert f"{v.mean:.3f} ± 0.000" in two and "over 2 seeds" in two
    with pytest.raises(Exception):
        tables([])


def test_plots_are_png_files_with_content_and_never_replace_a_users_file(result, tmp_path):
    out = tmp_path / "out"
    paths = write_report([result], out)
    assert [p.name for p in paths] == list(PLOT_FILES) + ["tables.md", "results.json"]
    for p in paths[:len(PLOT_FILES)]:
        w, h = png_size(p)
        assert w >= 500 and h >= 400 and p.stat().st_size > 20_000, p.name
    cv = result.cv
    with pytest.raises(ExportError):  # the plain plot functions never overwrite unasked
        plots.plot_cv_curve(cv.lambdas, cv.mean_error, cv.best_lambda, out / PLOT_FILES[0])
    assert [name for name, _ in figures(result)] == list(PLOT_FILES)
    again = write_report([result], out)  # the report replaces its own earlier files
    assert [p.name for p in again] == [p.name for p in paths]
    (out / "point_sets.png").write_bytes(PNG_SIGNATURE + b"a user's picture")
    with pytest.raises(ExportError, match="not written by"):
        write_report([result], out)
    assert (out / "point_sets.png").read_bytes().endswith(b"a user's picture")


def test_weak_and_dropped_parameters_are_known_to_the_deviation_plot(result):
    # the plot marks dropped (not identified) parameters and hatches weak ones: both flags
    # must be there, and a weak parameter is always an identified one
    for m in result.methods:
        assert m.weak.shape == m.identified.shape and not np.any(m.weak & ~m.identified)
    ls = result.method("ls_rtest")
    assert ls.weak.any() and not ls.identified.all()
    png = plots.plot_parameter_deviations(
        result.parameter_names, result.is_length,
        [(m.label, m.deviations, m.identified, m.weak) for m in result.methods[1:]]
        + [("Truth", result.true_deviations)], None)
    assert png[:8] == PNG_SIGNATURE


def test_plot_calibration_of_one_result(tmp_path):
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure, planted_table
    from kincal.robot import Robot

    rng = np.random.default_rng(3)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(40, g.n))
    truth = Truth(planted_table(model, rng), np.array([1.0, 0.2, 0.1, 0.01, 0.02, 0.3]),
                  np.array([0.03, 0.0, 0.1]))
    data = measure(model, truth, q, 5e-5, rng)
    res = CalibrationProblem(robot, data, CalibrationOptions(lam="cv", n_lambdas=6,
                                                                folds=3)).solve()
    figures = plots.calibration_figures(res)
    assert [name for name, _ in figures] == ["cv_curve.png", "residuals.png", "parameters.png"]
    assert not list(tmp_path.iterdir())  # nothing is written but through write_calibration
    for name, png in figures:
        (tmp_path / name).write_bytes(png)
        assert min(png_size(tmp_path / name)) >= 400 and len(png) > 10_000


def test_demo_writes_its_files_and_the_summary_matches(tmp_path):
    out = tmp_path / "demo"
    config = replace(ExperimentConfig.small(seed=1), n_lambdas=6, folds=3)
    s = demo(out, config)
    assert sorted(p.name for p in s.files) == sorted(REPORT_FILES)
    assert all(p.parent == out and p.stat().st_size > 0 for p in s.files)
    saved = json.loads((out / "results.json").read_text())
    assert saved["summary"] == s.numbers()
    methods = saved["results"][0]["methods"]
    assert methods["l2_rtest"]["validation"]["mean"] == s.l2_rtest_validation_mean_mm
    assert methods["ls_rtest"]["validation"]["mean"] == s.ls_rtest_validation_mean_mm
    assert methods["before"]["validation"]["mean"] == s.before_validation_mean_mm
    assert saved["results"][0]["lambda"] == s.lam
    assert f"{s.l2_rtest_validation_mean_mm:.3f}" in (out / "tables.md").read_text()
    for name in PLOT_FILES:
        png_size(out / name)
    # never a file it did not write
    (out / "tables.md").write_text("my notes\n")
    before = {n: (out / n).read_bytes() for n in REPORT_FILES}
    with pytest.raises(ExportError, match="not written by"):
        demo(out, config)
    assert {n: (out / n).read_bytes() for n in REPORT_FILES} == before
