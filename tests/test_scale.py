"""Many samples: block-wise evaluation, vectorised approach directions, CV on a subsample."""

import numpy as np
import pytest
from conftest import random_joint_values

from kincal.errors import OptionError
from kincal.identification import problem as calibration
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh
from kincal.models.backlash import approach_directions
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot

ROBOT = Robot.load("ec66")
MODEL = mdh.extract(ROBOT.geometry)
TOOLS = np.array([[0.03, 0.02, 0.12], [-0.04, 0.01, 0.1]])


def _data(n, seed=0, tools=TOOLS):
    rng = np.random.default_rng(seed)
    truth = Truth(planted_table(MODEL, rng), np.array([0.8, 0.3, -0.2, 0.02, -0.03, 1.2]),
                  tools)
    return measure(MODEL, truth, random_joint_values(ROBOT.geometry, rng, n), 5e-5, rng)


@pytest.mark.parametrize("kinematic", [True, False])
def test_blockwise_residual_equals_the_whole(monkeypatch, kinematic):
    # two points per pose and backlash terms: every sliced array takes part
    data = _data(50)
    opts = CalibrationOptions(method="ls", backlash=("joint_2", "joint_5"))
    p = CalibrationProblem(ROBOT, data, opts)
    u = p.start() / p.scale + np.random.default_rng(1).normal(size=p.scale.size) * 1e-2
    whole = p.residual_function(kinematic=kinematic)(u, True)
    monkeypatch.setattr(calibration, "BLOCK_SAMPLES", 7)  # 100 samples: 15 blocks
    rows = np.arange(3, 97)
    blocked = p.residual_function(kinematic=kinematic)(u, True)
    assert np.array_equal(whole[0], blocked[0]) and np.array_equal(whole[1], blocked[1])
    sub_blocked = p.residual_function(rows, kinematic)(u, True)
    monkeypatch.setattr(calibration, "BLOCK_SAMPLES", 10**9)
    sub_whole = p.residual_function(rows, kinematic)(u, True)
    assert np.array_equal(sub_whole[1], sub_blocked[1])
    assert np.array_equal(sub_whole[0], sub_blocked[0])


def _directions_one_by_one(q, order=None, tol=1e-3):
    """The definition, sample after sample (the reference for the vectorised version)."""
    seq = np.arange(len(q)) if order is None else np.argsort(order, kind="stable")
    out = np.zeros_like(q)
    for k in range(1, len(q)):
        step = q[seq[k]] - q[seq[k - 1]]
        out[seq[k]] = np.where(np.abs(step) > tol, np.sign(step), out[seq[k - 1]])
    return out


@pytest.mark.parametrize("n", [0, 1, 2, 3, 200])
def test_vectorised_approach_directions_follow_the_definition(n):
    rng = np.random.default_rng(n)
    # many repeated values and sub-tolerance steps, so the forward fill is exercised
    q = np.round(rng.normal(size=(n, 4)), 1) * (rng.random((n, 4)) < 0.5)
    q[rng.random((n, 4)) < 0.2] += 4e-4
    order = rng.permutation(n).astype(float)
    assert np.array_equal(approach_directions(q), _directions_one_by_one(q))
    assert np.array_equal(approach_directions(q, order), _directions_one_by_one(q, order))


def test_cv_on_a_subsample_of_many_poses_says_so():
    data = _data(80, seed=2)
    res = CalibrationProblem(ROBOT, data, CalibrationOptions(cv_max_poses=30,
                                                             n_lambdas=8)).solve()
    cv = res.cv
    assert cv.subsample == (30, 80)
    used = np.concatenate(cv.folds)
    assert len(used) == 60 and len(np.unique(used)) == 60  # 30 poses, both points of each
    assert len(np.unique(data.poses[used])) == 30
    for f in cv.folds:  # the points of a pose stay in one fold, indices are the data's
        assert all(np.sum(data.poses[f] == q) == 2 for q in np.unique(data.poses[f]))
    assert "on a random 30 of the 80 poses" in res.summary()
    assert res.lam == cv.best_lambda and len(res.residuals) == 160  # final fit on all
    assert cv.as_dict()["subsample_poses"] == [30, 80]
    full = CalibrationProblem(ROBOT, data, CalibrationOptions(cv_max_poses=None,
                                                              n_lambdas=8)).solve()
    assert full.cv.subsample is None and "random" not in full.summary()
    assert len(np.concatenate(full.cv.folds)) == 160


@pytest.mark.parametrize("bad", [1, 3, 2.5, True, "all"])
def test_bad_cv_max_poses_is_an_option_error(bad):
    with pytest.raises(OptionError, match="cv_max_poses"):
        CalibrationOptions(cv_max_poses=bad, folds=5).validated()


# ------------------------------------------------------------------ command line
def _ec66_csv(tmp_path, n=40):
    path = tmp_path / "d.csv"
    path.write_text(_data(n, tools=TOOLS[0]).to_csv_text())
    return path


def test_every_long_command_ends_with_a_timing_line(tmp_path, capsys):
    from kincal.cli.main import main

    csv = _ec66_csv(tmp_path)
    runs = {"calibrate": ["calibrate", "ec66", str(csv), "--method", "ls",
                          "--out", str(tmp_path / "c.urdf"), "--quiet"],
            "evaluate": ["evaluate", "ec66", str(csv), "--fit-frames"],
            "analyze": ["analyze", "ec66", str(csv)],
            "plan": ["plan", "ec66", "--random", "100", "--poses", "30",
                     "--out", str(tmp_path / "p.csv")],
            "simulate": ["simulate", "ec66", "--poses", "10", "--out", str(tmp_path / "s.csv")]}
    for name, argv in runs.items():
        assert main(argv) == 0, name
        err = capsys.readouterr().err.strip().splitlines()
        assert err and err[-1].startswith("kincal: done in ") and err[-1].endswith(" s"), name
    # an error stays one line, with no timing after it
    assert main(["analyze", "ec66", str(tmp_path / "missing.csv")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("kincal: error:")


class _Terminal:
    def __init__(self):
        self.text = ""

    def isatty(self):
        return True

    def write(self, s):
        self.text += s

    def flush(self):
        pass


def test_fit_status_speaks_only_for_long_fits_and_ends_its_line():
    from kincal.cli.progress import FitStatus as _FitStatus

    assert _FitStatus.on_terminal(_Terminal()) is not None
    assert _FitStatus.on_terminal(open(__file__)) is None  # not a terminal: no status

    quick = _FitStatus(_Terminal(), after=3600.0)
    quick(1, 100)
    quick.close()
    assert quick.stream.text == ""

    slow = _FitStatus(_Terminal(), after=0.0)
    data = _data(30, tools=TOOLS[0])
    from kincal.identification.solver import SolverOptions

    CalibrationProblem(ROBOT, data, CalibrationOptions(
        method="ls", solver=SolverOptions(progress=slow))).solve()
    slow.close()
    assert "\rsolving: iteration 1 (at most 100)" in slow.stream.text.replace("  solving",
                                                                              "solving")
    assert slow.stream.text.endswith("\n") and slow.stream.text.count("\n") == 1


def test_simulate_reports_progress_to_the_last_pose():
    from kincal.planning.simulation import cube_poses

    seen = []
    q = cube_poses(ROBOT, 250, [0.4, 0.0, 0.25], 0.4, [0, 0, 0.12],
                   np.random.default_rng(0), progress=lambda done, total: seen.append(done))
    assert len(q) == 250 and seen[0] == 0 and seen[-1] == 250
    assert seen == sorted(seen) and len(seen) > 100


def _plain_duplicates(sets):
    """The findings of checks.duplicate_samples as its first version made them: every
    sample's numbers as one void key, np.unique and np.isin over all of them."""
    def keys(d):
        n = len(d.joint_values)
        rows = np.ascontiguousarray(np.hstack([
            np.asarray(v, dtype=float).reshape(n, -1) for name in d.per_sample_fields()
            if name not in ("rows", "poses", "approach")
            for v in [getattr(d, name)] if v is not None]))
        return rows.view(np.dtype((np.void, 8 * rows.shape[1])))[:, 0]

    out, seen = [], []
    for d in sets:
        k, lines = keys(d), d.rows
        _, first, inverse = np.unique(k, return_index=True, return_inverse=True)
        earliest = first[inverse.ravel()]
        copies = np.flatnonzero(earliest != np.arange(len(k)))
        if copies.size:
            out.append(f"{d.source}: {copies.size} sample(s) repeat earlier ones exactly "
                       f"(line {lines[copies[0]]} repeats line {lines[earliest[copies[0]]]})")
        for o, ok in seen:
            if ok.dtype != k.dtype:
                continue
            both = np.flatnonzero(np.isin(k, ok))
            if both.size:
                j = int(np.flatnonzero(ok == k[both[0]])[0])
                out.append(f"{d.source}: {both.size} of its {len(k)} samples repeat samples of "
                           f"{o.source} exactly (line {lines[both[0]]} = line {o.rows[j]} "
                           "there: the same data given twice?)")
                break
        seen.append((d, k))
    return out


@pytest.mark.parametrize("collide", [False, True])
def test_duplicate_samples_are_the_exact_copies(monkeypatch, collide):
    """The gate's search for samples given twice (checks.duplicate_samples, repeated_samples,
    repeats_all) finds exactly the copies the plain search over every sample's numbers
    finds, with the same lines, -0.0 apart from 0.0; also when every hash collides (the
    multiplier 0 hashes every sample to 0): matching hashes are only candidates."""
    from dataclasses import replace

    from kincal.measurements import checks

    if collide:
        monkeypatch.setattr(checks, "_MIX", np.uint64(0), raising=False)
    rng = np.random.default_rng(5)
    base = _data(40)
    for trial in range(40):
        sets = []
        for s in range(int(rng.integers(1, 4))):
            n = int(rng.integers(2, 30))
            q = rng.integers(0, 3, (n, 6)) * 0.5  # few distinct values: many copies
            q[rng.random(n) < 0.3, 0] = -0.0
            q[rng.random(n) < 0.3, 0] = 0.0
            d = base.subset(np.arange(n))
            sets.append(replace(d, joint_values=q, positions=np.c_[rng.integers(0, 2, (n, 2)),
                                                                    np.arange(n) % 2 * 0.1],
                                sigma=None if rng.random() < 0.5 else np.full(n, 1e-4),
                                rows=np.arange(n) + 2 + 100 * s, source=f"set{s}"))
        assert checks.duplicate_samples(sets) == _plain_duplicates(sets)
        for a in sets:
            for b in sets:
                plain = _plain_duplicates([b, a])[-1:]
                found = checks.repeated_samples(a, b)
                assert [found] == plain if found else not [p for p in plain if "of its" in p]
                assert checks.repeats_all(a, b) == bool(found and found.split(": ")[1]
                                                       .startswith(f"{len(a.rows)} of its"))


def test_duplicate_samples_keep_the_memory_bounded():
    """The gate looks for copies among all samples after the fit (issue 20: memory linear
    with the fit's slope): 8-byte hashes and their sort, not every sample's numbers as keys
    sorted and copied (about 350 bytes per sample traced, which took the 300,000-pose
    command past its 1.0 KiB per pose)."""
    import tracemalloc

    from kincal.measurements import checks

    data = _data(100_000, tools=TOOLS[:1])
    data = data.subset(np.r_[np.arange(100_000), [7, 9]])  # two samples given twice
    tracemalloc.start()
    try:
        assert checks.duplicate_samples([data]) == [
            f"{data.source}: 2 sample(s) repeat earlier ones exactly (line {data.rows[7]} "
            f"repeats line {data.rows[7]})"]
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100 * len(data.rows)  # bytes
