"""The batched paths of the performance work against the arithmetic they replace: each new
path is compared with the old one (Pinocchio calls per pose, dense residual and Jacobian,
the per-pose loops) on seeded data, to 1e-9 or better."""

from __future__ import annotations

import numpy as np
import pytest
from chains import random_chain, random_tree, sample_robots

from kincal.models import workspace
from kincal.robot import Robot


def _robots(tmp_path):
    return sample_robots(tmp_path, ("ec66",))


def test_gate_tool_points_match_pinocchio(tmp_path):
    """The gate's tool points through the vectorised chain equal Pinocchio's, per pose."""
    rng = np.random.default_rng(0)
    for robot in _robots(tmp_path):
        g = robot.geometry
        lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
        hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
        q = rng.uniform(lo, hi, (40, g.n))
        q[0] = 0.0
        tool = rng.normal(size=3) * 0.1
        T = robot.tip_poses(q)
        want = T[:, :3, 3] + T[:, :3, :3] @ tool
        assert np.abs(workspace.tool_points(robot, q, tool) - want).max() < 1e-12


def _point_data(n, seed=0):
    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure, planted_table

    rng = np.random.default_rng(seed)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(n, g.n))
    tool = np.array([0.02, 0.01, 0.12])
    truth = Truth(planted_table(model, rng), np.array([0.8, 0.3, -0.2, 0.02, -0.03, 1.2]),
                  tool + [0.001, -0.001, 0.002])
    return robot, measure(model, truth, q, 5e-5, rng)


@pytest.mark.parametrize("method", ["ls", "l2"])
def test_streamed_fit_equals_the_dense_fit(method, monkeypatch):
    """Rows streamed in blocks (normal equations per block, stacked QR for the analysis)
    give the dense path's identifiable set, parameters and covariance."""
    from kincal.identification import problem as problem_module
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem

    robot, data = _point_data(300)
    opts = CalibrationOptions(method=method, lam=1e-3 if method == "l2" else "auto")
    results = {}
    for size in (10 ** 9, 64):  # one block: the dense J; 64 samples: five blocks
        monkeypatch.setattr(problem_module, "BLOCK_SAMPLES", size)
        problem = CalibrationProblem(robot, data, opts)
        assert problem.residual_function().n_blocks == (1 if size > 300 else 5)
        results[size] = problem.solve()
    dense, streamed = results[10 ** 9], results[64]
    assert dense.solve.jacobian is not None and streamed.solve.jacobian is None
    assert streamed.identifiability.kept == dense.identifiability.kept
    assert streamed.identifiability.dropped == dense.identifiability.dropped
    assert abs(streamed.identifiability.condition_number
               / dense.identifiability.condition_number - 1) < 1e-9
    assert np.abs(streamed.x - dense.x).max() < 1e-9
    assert np.abs(streamed.covariance - dense.covariance).max() < 1e-9 * np.abs(
        dense.covariance).max()
    assert np.abs(streamed.solve.residual - dense.solve.residual).max() < 1e-9
    free = np.isin(np.array(dense.layout.names), dense.identifiability.kept)
    B = streamed.solve.jacobian_root(free)
    J = dense.solve.jacobian[:, free]
    assert np.abs(B.T @ B - J.T @ J).max() < 1e-9 * np.abs(J.T @ J).max()


def test_reduction_against_one_qr():
    """The stacked QR and the Gram triangle against numpy's QR of the whole matrix; an
    ill-conditioned Gram matrix is refused rather than trusted."""
    from kincal.identification import reduction

    rng = np.random.default_rng(1)
    J, r = rng.normal(size=(500, 7)), rng.normal(size=500)
    blocks = [(slice(a, a + 100), r[a:a + 100], J[a:a + 100]) for a in range(0, 500, 100)]
    R, m = reduction.stacked_triangle(blocks, with_residual=True)
    R0 = np.linalg.qr(np.column_stack([J, -r]), mode="r")
    assert m == 500
    assert np.abs(np.abs(R) - np.abs(R0)).max() < 1e-12 * np.abs(R0).max()
    rr, G, g = reduction.normal_equations(blocks, 500, 7)
    assert np.array_equal(rr, r)
    Rz = reduction.triangle_from_gram(G, g, float(r @ r))
    assert np.abs(np.abs(Rz) - np.abs(R0)).max() < 1e-10 * np.abs(R0).max()
    J[:, 6] = J[:, 5] + 1e-9 * J[:, 0]  # cond ~ 1e9: Cholesky-QR is not trusted
    _, G, g = reduction.normal_equations(blocks, 500, 7)
    assert reduction.triangle_from_gram(G, g, float(r @ r)) is None


def test_chain_without_cached_motions_is_the_same(monkeypatch):
    """Many poses: joint motions made at each evaluation equal the cached ones."""
    from kincal.models import chain as chain_module
    from kincal.models import mdh

    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    q = np.random.default_rng(2).uniform(-3, 3, (50, 6))
    x = model.nominal + np.random.default_rng(3).normal(size=model.size) * 1e-3
    cached = chain_module.Chain(model, q).state(x)
    monkeypatch.setattr(chain_module, "MOTION_CACHE_POSES", 10)
    fresh = chain_module.Chain(model, q)
    assert fresh._motion is None
    state = fresh.state(x)
    assert np.array_equal(state.p_tip, cached.p_tip) and np.array_equal(state.R_tip, cached.R_tip)


def test_axis_rotations_are_rotation_vectors():
    """kincal's one Rodrigues formula (rotations.axis_rotations, one axis or one per angle)
    against scipy's rotation vectors, and the turn about an axis line (turn_parts) against
    R (x - c) + c; skew(v) u = v x u."""
    from scipy.spatial.transform import Rotation

    from kincal.rotations import axis_rotation, axis_rotations, skew, turn_parts

    rng = np.random.default_rng(4)
    for _ in range(5):
        w = rng.normal(size=3)
        w /= np.linalg.norm(w)
        q = np.concatenate([[0.0, np.pi, -np.pi / 2], rng.uniform(-7, 7, 500)])
        want = Rotation.from_rotvec(q[:, None] * w).as_matrix()
        assert np.abs(axis_rotations(w, q) - want).max() < 1e-14
        W = rng.normal(size=(len(q), 3))
        W /= np.linalg.norm(W, axis=1)[:, None]
        want = Rotation.from_rotvec(q[:, None] * W).as_matrix()
        assert np.abs(axis_rotations(W, q) - want).max() < 1e-14
        assert np.abs(axis_rotation(w, q[7]) - Rotation.from_rotvec(q[7] * w).as_matrix()
                      ).max() < 1e-14
        u = rng.normal(size=(4, 3))
        assert np.abs(np.einsum("ij,nj->ni", skew(w), u) - np.cross(w, u)).max() < 1e-15
        assert np.abs(skew(u) @ w - np.cross(u, w)).max() < 1e-15
        c, x = rng.normal(size=3), rng.normal(size=3)
        P = turn_parts(w, c)
        for a in q[:20]:
            T = np.cos(a) * P[0] + np.sin(a) * P[1] + (1 - np.cos(a)) * P[2]
            R = Rotation.from_rotvec(a * w).as_matrix()
            assert np.abs(T[:, :3] @ x + T[:, 3] - (R @ (x - c) + c)).max() < 1e-14


def test_cv_path_equals_fold_fits_from_scratch():
    """Algorithm 1 with each fold's warm start at exactly the previous solution and its
    linearisation remembered gives the curve of plain fold fits (a new residual and every
    linearisation evaluated, the start through SI units) to 1e-7, and the same lambda."""
    from dataclasses import replace

    from kincal.identification.cross_validation import cross_validate, remembering
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem

    robot, data = _point_data(60, seed=3)
    problem = CalibrationProblem(robot, data, CalibrationOptions(method="l2", lam="cv"))
    fast = problem.cross_validate()
    o, free = problem.options, problem.free_mask()
    solver = replace(o.solver, step_tol=max(o.solver.step_tol, o.cv_step_tol), progress=None)

    def plain(train, lam, start):
        return problem.fit(lam, train, None if start is None else start.u * problem.scale,
                           free, problem.residual_function(train), solver)

    def error(sol, val):
        (_, e), = problem.sample_errors(sol.u * problem.scale, val)
        return float(np.mean(e)) * 1e3

    slow = cross_validate(plain, error, problem.n_samples, fast.lambdas, o.fold_count, o.seed,
                          groups=data.poses)
    assert fast.best_lambda == slow.best_lambda
    # 1e-7: a fold fit whose stop is borderline (seed 3, lambda 1.5e-6: 0 iterations or 1)
    # may go either way with the last bit of its start (6e-9 seen after a rounding-level
    # change of the point start, 2026-11-24)
    assert np.abs(fast.fold_errors / slow.fold_errors - 1).max() < 1e-7
    # the remembered residual gives what it was asked for, not what it saw last
    residual = remembering(problem.residual_function())
    u = problem.start() / problem.scale
    r0, J0 = residual(u, True)
    v = u + 1e-3
    r1, J1 = residual(v, True)
    assert residual(u, True)[0] is r0 and not np.array_equal(r0, r1)
    assert np.array_equal(residual(v, True)[1], problem.residual_function()(v, True)[1])


def test_solver_lstsq_is_scipys_to_the_bit():
    """The solver's direct gelsy call gives scipy.linalg.lstsq's answer, bit for bit: tall,
    square, wide and rank-deficient systems."""
    import scipy.linalg

    from kincal.identification.linalg import lstsq

    rng = np.random.default_rng(6)
    for m, n in ((190, 45), (45, 45), (20, 45), (60, 7)):
        A, b = rng.normal(size=(m, n)), rng.normal(size=m)
        if m == 60:
            A[:, 3] = A[:, 1] - 2 * A[:, 2]
        want = scipy.linalg.lstsq(A, b, cond=1e-15, lapack_driver="gelsy",
                                  check_finite=False)[0]
        assert np.array_equal(lstsq(A, b), want)


def test_set_residuals_in_blocks_equal_the_whole_set(monkeypatch):
    """A set's residuals and sample errors evaluated in the fit's blocks (many poses) equal
    one evaluation of the whole set."""
    from kincal.identification import problem as problem_module
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem

    robot, data = _point_data(300, seed=7)
    monkeypatch.setattr(problem_module, "BLOCK_SAMPLES", 64)
    problem = CalibrationProblem(robot, data, CalibrationOptions(method="ls"))
    x = problem.start() + 1e-4
    whole = problem.kinds[0].residuals(*problem.layout.split(x, 0))
    assert len(problem._blocks(0, problem.kinds[0], None, True)) == 5
    assert np.abs(problem.residuals(x, 0) - whole).max() < 1e-15
    (_, e), = problem.sample_errors(x)
    assert np.abs(e - np.linalg.norm(whole, axis=1)).max() < 1e-15


def test_first_guess_from_spread_samples_reaches_the_same_start(monkeypatch):
    """Many samples: the closed-form guess of the frames from samples spread through the
    set, refined on all of them, is the start made from every sample."""
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.measurements import point

    robot, data = _point_data(300, seed=8)
    full = CalibrationProblem(robot, data, CalibrationOptions(method="ls")).start()
    monkeypatch.setattr(point, "START_SAMPLES", 40)
    assert len(data) > point.START_SAMPLES
    spread = CalibrationProblem(robot, data, CalibrationOptions(method="ls")).start()
    assert np.abs(spread - full).max() < 1e-9


def test_lapack_from_scipys_file_is_the_public_routine():
    """Loaded from scipy's extension file (no scipy.linalg package import) or by the public
    get_lapack_funcs, the solver's gelsy gives the same answer to the bit, and its QR
    triangle (dgeqrf through the same wrappers) is scipy.linalg.qr's to the bit and numpy's
    np.linalg.qr(A, mode="r") to rounding (the same routine in another build of LAPACK; on
    this project's machine the same bits)."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from kincal.identification.linalg import _routines, qr_r, lstsq\n"
        "rng = np.random.default_rng(3); A = rng.normal(size=(50, 9)); b = rng.normal(size=50)\n"
        "fast = lstsq(A, b)\n"
        "B = rng.normal(size=(150, 46)) * np.logspace(0, 8, 46)\n"
        "tri = [qr_r(M) for M in (B, B[:40], np.asfortranarray(B), B[:, :9].T)]\n"
        "print('LINALG:', 'scipy.linalg' in sys.modules)\n"
        "import scipy.linalg\n"
        "want = scipy.linalg.lstsq(A, b, cond=1e-15, lapack_driver='gelsy', check_finite=False)[0]\n"
        "public = _routines()\n"
        "mats = (B, B[:40], B, B[:, :9].T)\n"
        "qr = all(np.array_equal(t, scipy.linalg.qr(M, mode='r', check_finite=False)[0][\n"
        "                                       :min(M.shape)]) for t, M in zip(tri, mats))\n"
        "near = max(np.abs(t - np.linalg.qr(M, mode='r')).max() / np.abs(t).max()\n"
        "           for t, M in zip(tri, mats))\n"
        "print('SAME:', np.array_equal(fast, want), qr, near < 1e-13, public[0].__name__,\n"
        "      public[2].__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True).stdout.split("\n")
    assert out[0] == "LINALG: False" and out[1].startswith("SAME: True True True"), out
    assert "dgelsy" in out[1] and "dgeqrf" in out[1], out


@pytest.mark.parametrize("spread", [1.0, 0.1, 0.0])
def test_frame_start_from_sums_equals_the_stacked_rows(spread):
    """The closed-form start's rounds on 3 x 3 sums give the frame and tool point of the
    rounds on the stacked (3N, 6) rows; tip orientations all alike (spread 0) take the
    stacked rows themselves (their minimum-norm answer). Starts run together give each
    start's numbers alone, to the bit."""
    from kincal.measurements import frames_init
    from kincal.rotations import base_rotation

    rng = np.random.default_rng(7)
    R = np.array([base_rotation(*rng.uniform(-spread, spread, 3)) for _ in range(60)])
    p = rng.uniform(-0.5, 0.5, (60, 3))
    tool = np.array([0.02, 0.01, 0.12])
    P = (p + R @ tool) @ base_rotation(0.1, 0.2, 0.3).T + [1.0, 2.0, 3.0]
    P += 1e-5 * rng.normal(size=P.shape)
    starts = (np.zeros(3), frames_init.pivot_tool(R, p))
    together = frames_init.alternate(R, p, P, starts)  # the starts' rounds stacked
    for t0, both in zip(starts, together):
        got = frames_init.alternate(R, p, P, [t0])[0]
        assert all(np.array_equal(a, b) for a, b in zip(got, both))  # each start's own bits
        want = frames_init._alternate_rows(R, p, P, np.array(t0, float), 8)
        for a, b in zip(got, want):
            assert np.abs(np.asarray(a) - np.asarray(b)).max() < 1e-9
        if spread == 0.0:
            assert all(np.array_equal(a, b) for a, b in zip(got, want))


def test_fit_starts_from_the_analysis_pass(monkeypatch):
    """The fit's first linearisation is the Jacobian the identifiability analysis made at
    the same start (no second pass), and the result is that of a fit that makes its own."""
    from kincal.identification import reduction
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem

    robot, data = _point_data(60)
    used = []
    pop = dict.pop

    class Spy(dict):
        def pop(self, key, default=None):
            out = pop(self, key, default)
            used.append(out is not None)
            return out

    class Forgetful(dict):
        def __setitem__(self, key, value):
            pass

    def fits(memo_class):
        made = reduction.residual_function

        def residual_function(*args, **kwargs):
            out = made(*args, **kwargs)
            out.memo = memo_class()
            return out

        monkeypatch.setattr(reduction, "residual_function", residual_function)
        import kincal.identification.problem as problem_module

        monkeypatch.setattr(problem_module, "residual_function", residual_function)
        return [CalibrationProblem(robot, data, CalibrationOptions(method=m)).solve()
                for m in ("ls", "l2")]

    reused = fits(Spy)
    assert any(used)
    fresh = fits(Forgetful)
    for a, b in zip(reused, fresh):
        assert np.array_equal(a.x, b.x) and a.identifiability.kept == b.identifiability.kept


def test_error_models_are_built_once_per_geometry():
    """Every fit of one robot shares its error models (built once per geometry object),
    read-only, equal to a fresh build; a corrected robot (a new geometry) gets its own."""
    from kincal import models

    robot = Robot.load("ec66")
    for name in models.MODELS:
        a = models.build(name, robot.geometry)
        assert models.build(name, robot.geometry) is a
        fresh = models._build(name, robot.geometry)
        for key, value in vars(fresh).items():
            if isinstance(value, np.ndarray):
                assert np.array_equal(getattr(a, key), value)
                with pytest.raises(ValueError):
                    getattr(a, key)[...] = 0.0
    moved = robot.geometry.joint_frames.copy()
    moved[2, 0, 3] += 1e-3
    other = robot.with_joint_frames(moved)
    b = models.build("complete", other.geometry)
    assert b is not models.build("complete", robot.geometry)
    assert not np.array_equal(b.nominal, models.build("complete", robot.geometry).nominal)


def test_kept_per_robot_equals_made_afresh():
    """What a fit keeps per robot (the structural analysis's seeded poses, the gate's
    nominal tip poses) gives what making it afresh gives, to the bit, and a second data set
    of the same robot reuses it."""
    from kincal import models
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem

    robot, data = _point_data(60)
    _, other = _point_data(60, seed=1)
    runs = []
    for clear in (True, False, True):
        if clear:
            models._MEMO.clear()
        for d in (data, other):
            problem = CalibrationProblem(robot, d, CalibrationOptions(method="ls"))
            result = problem.solve()
            runs.append((problem.structural(), result.plausibility.evidence))
    for k in range(2):
        first = runs[k]
        for again in runs[k::2][1:]:
            assert first[0].kept == again[0].kept and np.array_equal(first[0].singular_values,
                                                             again[0].singular_values)
            assert first[1] == again[1]
    assert any(key[0][0] == "gate configurations" for key in models._MEMO)
    assert any(key[0][0] == "structural poses" for key in models._MEMO)


def test_a_robots_kept_models_outlive_one_off_geometries():
    """Each fit's corrected robot is a new geometry: many of them (more than the memo
    holds) do not push out the models of the robot that every fit uses."""
    from kincal import models

    robot = Robot.load("ec66")
    kept = models.build("complete", robot.geometry)
    frames = robot.geometry.joint_frames.copy()
    for k in range(models._MEMO_MAX + 10):
        frames[1, 2, 3] += 1e-6
        models.build("offsets", robot.with_joint_frames(frames).geometry)
        assert models.build("complete", robot.geometry) is kept
    assert len(models._MEMO) <= models._MEMO_MAX


def test_kept_only_is_the_analysis_partition():
    """selection.identifiable (the frame start's) keeps exactly what analyze keeps: full
    rank, exact duplicates, a run of nearly parallel columns (analyze's rank guard), fixed
    columns, and the triangle of many rows."""
    from kincal.identification.selection import analyze, identifiable

    rng = np.random.default_rng(3)
    names = tuple(f"j{i // 4}.{'a alpha d theta'.split()[i % 4]}" for i in range(12)) + (
        "base.x", "base.y", "base.z", "tool.x", "tool.y", "tool.z")
    cases = []
    J = rng.normal(size=(90, 18))
    cases.append((J, None))
    D = J.copy()
    D[:, 5] = D[:, 1] - 2 * D[:, 14]
    cases.append((D, None))
    P = J.copy()
    for c in (2, 6, 10):
        P[:, c] = P[:, 0] + 1e-9 * rng.normal(size=90)
    cases.append((P, None))
    free = np.ones(18, dtype=bool)
    free[[3, 15]] = False
    cases.append((D, free))
    for A, f in cases:
        assert identifiable(A, names, 12, f) == analyze(A, names, 12, f).kept
        R = np.linalg.qr(A, mode="r")
        assert identifiable(R, names, 12, f, m=90) == analyze(R, names, 12, f, m=90).kept


def test_offsets_at_zero_are_the_origins(tmp_path):
    """The offsets model at zero offsets (the URDF chain, ChainKinematics) places each joint
    at its origin: the same placements as the offset motions' product, and the same tip
    points through the chain."""
    from kincal.models import build

    for robot in _robots(tmp_path):
        model = build("offsets", robot.geometry)
        zero = np.zeros(model.n)
        fast = model.placements(zero)
        slow = np.array([model.origins[i] @ model._offset(i, 0.0) for i in range(model.n)])
        assert np.array_equal(fast, slow)
        fast[...] = 0.0  # a copy: the shared model is untouched
        assert np.array_equal(model.placements(zero), slow)


def test_tied_duplicates_read_the_same_streamed_and_dense(tmp_path, monkeypatch):
    """A dropped parameter reproduced by several others with equal coefficients (the base's
    tilt by the three planes' tilts, each -1): the report lists them in one order whether
    the analysis reads the whole J or its triangle streamed in blocks, the kept columns'
    order (it followed the solve's rounding: plane3, plane1, plane2 on one path, another
    order on the other)."""
    from kincal.cli import main
    from kincal.identification import problem as problem_module
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.measurements.sets import read_set_file

    path = tmp_path / "planes.csv"
    assert main(["simulate", "ec66", "--kind", "plane", "--poses", "300", "--seed", "1",
                 "--out", str(path), "-q"]) == 0
    robot = Robot.load("ec66")
    data = read_set_file(path, robot.joint_names, on_plane=True)
    why = {}
    for size in (10 ** 9, 64):
        monkeypatch.setattr(problem_module, "BLOCK_SAMPLES", size)
        ident = CalibrationProblem(robot, data, CalibrationOptions(method="ls")).analyze()
        why[size] = [d.describe() for d in ident.duplicates]
    assert "joint_1.alpha ~ -1 plane1.rx -1 plane2.rx -1 plane3.rx" in why[64]
    assert why[64] == why[10 ** 9]
