"""The per-fit fixed cost's shortcuts against what they replace (issue 20): the corrected
robot built from the nominal one's parts against a full rebuild, the gate's corrected chain
on the nominal chain's joint motions against one made anew, the structural analysis's kept
names without its report, the frame start's rotation; each equal to the bit."""

from __future__ import annotations

import numpy as np
from chains import random_chain, random_tree, sample_robots

from kincal import models
from kincal.models import workspace
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.robot import Robot


def _robots(tmp_path):
    return sample_robots(tmp_path, ("ec66", "ur10"))


def _corrected(robot, rng):
    """The robot corrected by a random identified vector of its default error model."""
    model = models.build(models.default_for(robot.geometry), robot.geometry)
    x = model.nominal + rng.normal(size=model.size) * np.where(model.is_length, 1e-3, 2e-3)
    return robot.with_joint_frames(model.joint_frames(x))


def test_corrected_robot_equals_a_rebuild(tmp_path):
    """with_joint_frames reuses the nominal robot's chain, axes, kinds and limits: every
    field of its geometry, its URDF origins and Pinocchio's tip poses equal those of a Robot
    built from scratch on the same corrected Pinocchio model."""
    rng = np.random.default_rng(0)
    for robot in _robots(tmp_path):
        fast = _corrected(robot, rng)
        slow = Robot(fast.model, robot.urdf_text, robot.name, robot.base, robot.tip,
                     robot.source, robot.off_chain)
        a, b = fast.geometry, slow.geometry
        assert a.joint_names == b.joint_names and a.kinds == b.kinds
        for f in ("joint_frames", "axes", "T_base_tip", "lower", "upper", "parent_frames",
                  "reversed"):
            u, v = getattr(a, f), getattr(b, f)
            assert (u is None and v is None) or np.array_equal(u, v), f
        assert not np.array_equal(a.joint_frames, robot.geometry.joint_frames)
        q = rng.uniform(-1.0, 1.0, (5, a.n))
        assert np.array_equal(fast.tip_poses(q), slow.tip_poses(q))
        o1, o2 = fast.urdf_origins(), slow.urdf_origins()
        assert o1.keys() == o2.keys() and all(np.array_equal(o1[k], o2[k]) for k in o1)
        assert fast._chain == slow._chain and fast._reversed == slow._reversed
        assert fast.off_chain == slow.off_chain and fast._data is not robot._data


def test_gate_points_on_the_kept_motions_equal_points_made_anew(tmp_path):
    """The gate's tool points on its seeded configurations' motion coefficients (kept per
    robot, read-only) equal those of a chain made anew with its own, to the bit, for the
    nominal robot and a corrected one, and equal Pinocchio's (1e-12)."""
    from kincal.models.kinematics import ChainKinematics

    rng = np.random.default_rng(1)
    for robot in _robots(tmp_path):
        q, motions = workspace.configurations(robot)
        assert not q.flags.writeable and not motions.flags.writeable
        tool = rng.normal(size=3) * 0.1
        for r in (robot, _corrected(robot, rng)):
            fast = workspace.tool_points(r, q, tool, motions)
            assert np.array_equal(fast, ChainKinematics(r.geometry).tip_points(q, tool))
            T = r.tip_poses(q[:20])
            assert np.abs(fast[:20] - (T[:, :3, 3] + T[:, :3, :3] @ tool)).max() < 1e-12
        assert ChainKinematics.of(robot.geometry) is ChainKinematics.of(robot.geometry)


def test_structural_kept_is_the_structural_analysis():
    """The fit's uses of the structural analysis read its kept names without its report:
    the same names as the full analysis, with few poses (parameters lost to the data, the
    note and the too-few-poses error) and many."""
    from kincal.errors import IdentifiabilityError
    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure, planted_table

    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    for n, method in ((6, "l2"), (8, "ls"), (60, "ls")):
        rng = np.random.default_rng(n)
        q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), (n, g.n))
        truth = Truth(planted_table(model, rng), np.zeros(6), np.array([0.02, 0.01, 0.12]))
        data = measure(model, truth, q, 5e-5, rng)
        problem = CalibrationProblem(robot, data, CalibrationOptions(method=method, lam=0.01))
        kept = problem._structural_kept()
        again = CalibrationProblem(robot, data, CalibrationOptions(method=method, lam=0.01))
        assert kept == again.structural().kept and again._structural_kept() == kept
        if n == 8:  # fewer equations than the chain's identifiable parameters
            try:
                problem.solve()
                raise AssertionError("8 poses fitted by ls")
            except IdentifiabilityError as e:
                assert f"for the {len(kept)} parameters" in str(e)
        else:
            ident = problem.analyze()
            lost = [k for k in kept if k not in ident.kept]
            assert bool(lost) == (n == 6)
            assert any(f"{len(lost)} parameters this chain can identify" in s
                       for s in ident.notes) == bool(lost)


def test_frame_start_rotation_is_kabsch_with_its_diagonal():
    """The frame start's rotation V U^T (or with the last column of V negated) is Kabsch's
    V diag(1, 1, det) U^T to the bit, proper rotations and reflections alike (kabsch's own
    rotation, as it was made before it took this one)."""
    from kincal.rotations import kabsch_rotation as _rotation

    rng = np.random.default_rng(2)
    seen = set()
    for k in range(3000):
        H = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-6, 6)
        U, _, Vt = np.linalg.svd(H)
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
        assert np.array_equal(_rotation(H), Vt.T @ D @ U.T)
        seen.add(D[2, 2])
    assert seen == {1.0, -1.0}


def test_chain_keeps_its_first_and_last_states_only_for_the_same_values():
    """A chain of few poses serves the state at the values of its first two evaluations and
    of its last (a frame fit's evaluations are all at one kinematics; the start's come back for
    the residuals before calibration, and at every fit on a robot's seeded poses) with the
    numbers a new chain gives, tip and kept frames alike, read-only; other kinematic or
    joint-term values are evaluated anew."""
    from kincal.models.chain import Chain

    robot = Robot.load("ec66")
    model = models.build("complete", robot.geometry)
    rng = np.random.default_rng(4)
    q = rng.uniform(-2.0, 2.0, (40, model.n))
    approach = rng.choice([-1.0, 1.0], (40, model.n))
    x = model.nominal + rng.normal(size=model.size) * 1e-3
    b = np.array([1e-3])
    chain = Chain(model, q, approach, (2,))
    P = rng.normal(size=(40, 3))
    for values, terms in ((x, None), (x, b), (x + 1e-9, b), (x, np.zeros(1)), (x, None),
                          (x + 1e-9, b), (x, None), (x - 1e-9, None)):
        for keep in (False, True, False, True):
            s = chain.state(values, terms, keep=keep)
            fresh = Chain(model, q, approach, (2,)).state(values, terms, keep=True)
            assert np.array_equal(s.R_tip, fresh.R_tip) and np.array_equal(s.p_tip, fresh.p_tip)
            assert not s.R_tip.flags.writeable and not s.p_tip.flags.writeable
            if keep:
                assert np.array_equal(s.before, fresh.before)
                assert np.array_equal(s.placed, fresh.placed)
                for a, c in zip(s.point_columns(P), fresh.point_columns(P)):
                    assert np.array_equal(a, c)
    # the first two values and the last: (x, no terms), (x, b), then (x - 1e-9, no terms);
    # the frames of the first only
    assert [e[0] for e in chain._kept] == [(x.tobytes(), None), (x.tobytes(), b.tobytes()),
                                           ((x - 1e-9).tobytes(), None)]
    assert [e[3] is not None for e in chain._kept] == [True, False, False]
    served = chain.state(x, None, keep=True)
    assert not served.before.flags.writeable and not served.placed.flags.writeable
    assert np.shares_memory(served.R_tip, chain.state(x, None, keep=False).R_tip)
    assert np.shares_memory(served.before, chain.state(x, None, keep=True).before)
    assert not np.shares_memory(chain.state(x, b, keep=True).before,
                                chain.state(x, b, keep=True).before)  # made anew each time
    other = chain.state(x + 2e-9, None, keep=False)
    assert not np.shares_memory(other.R_tip, served.R_tip)


def test_kept_of_the_free_columns_alone_is_the_analysis_partition():
    """identifiable of the free columns alone (the frame start's: its kinematic columns are
    held) keeps what analyze keeps of the whole Jacobian: random columns with duplicates,
    near duplicates (1e-7 apart, the tolerance), a run of nearly parallel columns, held
    columns of every kind, and the frame start's own Jacobians of several robots."""
    from kincal.identification.selection import analyze, identifiable
    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure, planted_table

    rng, robots = np.random.default_rng(6), 0
    names = tuple(f"j{i // 4}.{'a alpha d theta'.split()[i % 4]}" for i in range(12)) + (
        "base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz", "tool.x", "tool.y",
        "tool.z", "j1.backlash")
    cases = []
    for k in range(60):
        J = rng.normal(size=(90, 22)) * 10.0 ** rng.uniform(-3, 3, 22)
        a, b, c = rng.choice(22, 3, replace=False)
        J[:, a] = J[:, b] * rng.normal() + J[:, c] * rng.normal()
        if k % 3 == 0:
            J[:, c] += 10.0 ** rng.uniform(-9, -5) * rng.normal(size=90) * np.abs(J[:, c]).max()
        if k % 5 == 0:
            for d in rng.choice(22, 4, replace=False):
                J[:, d] = J[:, b] + 1e-9 * rng.normal(size=90)
        free = rng.random(22) < 0.7
        free[rng.integers(22)] = False
        cases.append((J, free))
    for name in ("ec66", "ur10"):
        robot = Robot.load(name)
        model = mdh.extract(robot.geometry)
        g = robot.geometry
        q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), (30, g.n))
        for tool in ((0.02, 0.01, 0.12), (0.0, 0.0, 0.0)):
            truth = Truth(planted_table(model, rng), np.zeros(6), np.array(tool))
            data = measure(model, truth, q, 5e-5, rng)
            problem = CalibrationProblem(robot, data, CalibrationOptions(method="ls"))
            lay = problem.layout
            _, J = problem.residual_function(kinematic=False)(problem.x_nominal / problem.scale,
                                                              True)
            cases.append((J * lay.reporting_scale() / problem.scale, lay.is_frame.copy()))
            robots += 1
    seen = 0
    for J, free in cases:
        p = J.shape[1]
        nm = names if p == len(names) else tuple(f"j{i}.theta" for i in range(p - 9)) + names[
            12:21]
        nk = 12 if p == len(names) else p - 9
        whole = analyze(J, nm, nk, free).kept
        assert identifiable(J, nm, nk, free) == whole
        seen += len(whole) < int(free.sum())
    assert seen >= 10 and robots == 4  # cases that drop some free column; the robots'


def _projected_one_by_one(J, order, free, norms, rank_tol, scale):
    """The ordered selection as it was before the blocked one: each free column in turn
    projected off the kept ones' orthonormal basis (twice), kept when the rest is larger
    than rank_tol of its norm."""
    import math

    basis, kept, dropped = np.zeros(J.shape), [], []
    for c in order:
        if not free[c]:
            continue
        if norms[c] <= rank_tol * scale:
            dropped.append(c)
            continue
        r = J[:, c]
        if kept:
            Q = basis[:, :len(kept)]
            r = r - Q @ (Q.T @ r)
            r = r - Q @ (Q.T @ r)
        size = math.sqrt(r @ r)
        if size > rank_tol * norms[c]:
            basis[:, len(kept)] = r / size
            kept.append(c)
        else:
            dropped.append(c)
    return sorted(kept), sorted(dropped)


def test_blocked_selection_is_the_column_by_column_projection(tmp_path):
    """The ordered selection by one QR per run of drops keeps and drops exactly what the
    projection of one column at a time does: random columns with exact and near duplicates
    (1e-9 to 1e-5 apart, across the tolerance), zero columns, runs of nearly parallel
    columns, fewer rows than columns, held columns; and the Jacobians of the fits of several
    robots (random chains, a tree path), with a tool point off and on the last axis."""
    from kincal.errors import OptionError
    from kincal.identification.selection import _ordered, preference_order
    from kincal.measurements.point import MeasurementModel

    rng = np.random.default_rng(8)
    cases = []
    for k in range(400):
        p = int(rng.integers(3, 40))
        m = int(rng.integers(max(1, p // 3), 3 * p))
        J = rng.normal(size=(m, p)) * 10.0 ** rng.uniform(-3, 3, p)
        for _ in range(int(rng.integers(0, 5))):
            a, b, c = rng.choice(p, 3)
            J[:, a] = J[:, b] * rng.normal() + J[:, c] * rng.normal()
        if k % 3 == 0:
            c = rng.integers(p)
            J[:, c] += 10.0 ** rng.uniform(-9, -5) * rng.normal(size=m) * np.abs(J[:, c]).max()
        if k % 7 == 0:
            J[:, rng.integers(p)] = 0.0
        if k % 5 == 0:
            b = rng.integers(p)
            for d in rng.choice(p, 4):
                J[:, d] = J[:, b] + 1e-9 * rng.normal(size=m)
        cases.append((J if m <= p else np.linalg.qr(J, mode="r"), list(rng.permutation(p)),
                      rng.random(p) < 0.8))
    for robot in sample_robots(tmp_path, ("ec66", "ur10")):
        for name in ("mdh", "complete", "offsets"):
            try:
                model = models.build(name, robot.geometry)
            except OptionError:  # MD-H cannot describe a tree path
                continue
            q = rng.uniform(-2.0, 2.0, (int(rng.integers(4, 40)), model.n))
            for tool in (rng.normal(size=3) * 0.1, np.zeros(3)):
                mm = MeasurementModel(model, q)
                x = np.concatenate([model.nominal, rng.normal(size=6) * 0.1, tool])
                _, Jm = mm.jacobian(x)
                J = Jm.reshape(-1, x.size)
                names = tuple(model.names) + tuple(f"base.{c}" for c in
                                                   ("x", "y", "z", "rx", "ry", "rz")) + (
                    "tool.x", "tool.y", "tool.z")
                order = preference_order(names, model.size)
                cases.append((np.linalg.qr(J, mode="r") if len(J) > x.size else J, order,
                              np.ones(x.size, dtype=bool)))
    assert len(cases) >= 400 + 20  # every robot: three models, or offsets alone (a tree)
    dropping = []
    for J, order, free in cases:
        norms = np.linalg.norm(J, axis=0).tolist()
        scale = max(norms)
        old = _projected_one_by_one(J, order, free.tolist(), norms, 1e-7, scale)
        assert _ordered(J, order, free.tolist(), norms, 1e-7, scale) == old
        dropping.append(bool(old[1]))
    assert sum(dropping[:400]) >= 250 and sum(dropping[400:]) >= 10  # rank-deficient ones


def test_start_pass_is_what_the_analysis_and_the_fits_made_apart(monkeypatch):
    """The start's one pass (reduction.one_pass: the whole Jacobian at the start, its frame
    columns for the frame fit) changes nothing: every kind's frame columns are the same
    numbers with or without the kinematic ones, and a calibration with it equals one that
    makes the frame fit's and the analysis's passes apart (parameters, start, partition,
    notes, the gate's verdict), for point, pose, distance, plane and flush sets, one set or
    two, noisy (the frame fit moving or not) or not."""
    from kincal.identification import problem as problem_module
    from kincal.planning import kind_simulation as ks

    robot = Robot.load("ur10")
    em = models.build("complete", robot.geometry)
    rng = np.random.default_rng(11)
    g = robot.geometry
    lo, hi = np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi)
    q = rng.uniform(lo, hi, (40, g.n))
    cand = rng.uniform(lo, hi, (1500, g.n))
    kin = em.nominal + rng.normal(size=em.size) * np.where(em.is_length, 2e-4, 2e-4)
    base, tool = np.array([1.0, 0.5, 0.2, 0.1, -0.2, 0.3]), np.array([0.03, 0.02, 0.12])
    planes = np.array([[0.0, 0.0, 0.3], [np.pi / 2, 0.0, 0.2], [0.3, 1.2, 0.3]])
    cases = []
    for noise in (0.0, 5e-5):
        point = ks.simulate_points(em, kin, base, tool, q, noise, rng)
        cases += [[point],
                  [ks.simulate_poses(em, kin, base, np.r_[tool, 0.1, 0.2, -0.3], q, noise,
                                     0.01, rng)],
                  [ks.simulate_distances(em, kin, np.array([0.4, 0.3, 0.1]), tool, q, noise,
                                         rng)],
                  [ks.simulate_contacts(em, kin, tool, planes, cand, 25, noise, rng)],
                  [ks.simulate_flush(em, kin, np.r_[tool, 0.1, -0.1], planes, cand, 25, noise,
                                     0.01, rng)],
                  [point, ks.simulate_distances(em, kin, np.array([0.4, 0.3, 0.1]), tool, q,
                                                noise, rng)]]
    apart = lambda whole, frames_only, u, is_frame: None  # noqa: E731 (the passes apart)
    for sets in cases:
        options = CalibrationOptions(method="ls", model="complete")
        problem = CalibrationProblem(robot, sets, options)
        u = problem.start() / problem.scale + 1e-7
        r0, J0 = problem.residual_function(kinematic=False)(u, True)
        r1, J1 = problem.residual_function()(u, True)
        frame = problem.layout.is_frame
        assert np.array_equal(r0, r1) and np.array_equal(J0[:, frame], J1[:, frame])
        assert not J0[:, ~frame].any()
        results = []
        for one_pass in (problem_module.one_pass, apart):
            monkeypatch.setattr(problem_module, "one_pass", one_pass)
            results.append(CalibrationProblem(robot, sets, options).solve())
        a, b = results
        assert np.array_equal(a.x, b.x) and np.array_equal(a.x_start, b.x_start)
        assert a.identifiability.kept == b.identifiability.kept
        assert a.identifiability.notes == b.identifiability.notes
        assert repr(a.plausibility) == repr(b.plausibility)  # (NaN evidence: not ==)


def test_error_statistics_are_numpys_to_the_bit():
    """The statistics of a set's errors (mean, max, std with ddof 1, RMS, median) by the
    reductions themselves equal numpy's functions to the bit: odd and even counts, one and
    two values, ties, scales from um to km, a NaN (all NaN but n); the rows' norms are
    np.linalg.norm's."""
    import warnings

    from kincal.identification.statistics import ErrorStats, _summary

    def numpys(d):
        return (d.size, float(d.mean()), float(d.max()),
                float(d.std(ddof=1)) if d.size > 1 else 0.0, float(np.sqrt(np.mean(d ** 2))),
                float(np.median(d)))

    rng = np.random.default_rng(7)
    for k in range(3000):
        n = (1, 2, 3)[k] if k < 3 else int(rng.integers(1, 300))
        d = np.abs(rng.normal(size=n)) * 10.0 ** rng.uniform(-6, 3)
        if k % 5 == 0:
            d = np.round(d, 1)  # ties
        assert _summary(d) == numpys(d)
        e = rng.normal(size=(n, 3))
        assert ErrorStats.from_errors(e) == ErrorStats(*numpys(np.linalg.norm(e, axis=1) * 1e3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        d = np.array([0.2, np.nan, 0.1, 0.3])
        assert str(_summary(d)) == str(numpys(d)) == str((4,) + (float("nan"),) * 5)


def test_last_axis_distance_is_np_cross_to_the_bit():
    """The tool point's distance from the last axis (the fit's tool-axis note), its cross
    product in Python numbers, equals np.cross's to the bit, on every error model."""
    rng = np.random.default_rng(8)
    for name in ("ec66", "ur10"):
        g = Robot.load(name).geometry
        for model in (models.build(m, g) for m in models.MODELS):
            for _ in range(200):
                tool = rng.normal(size=3) * 10.0 ** rng.uniform(-4, 0)
                p = model.T_last_tip[:3, :3] @ tool + model.T_last_tip[:3, 3]
                want = np.linalg.norm(np.cross(p - model.screw_points[-1], model.screw_axes[-1]))
                assert model.last_axis_distance(tool) == float(want)


def test_chain_motions_and_placements_of_one_vector_are_the_per_joint_numbers(tmp_path):
    """A chain's kept joint motions (the revolute joints' in one stacked product) are
    joint_motion's per joint, and MD-H placements of one vector (entry by entry in Python
    numbers) are those of the array path, to the bit (signs of zeros too), on robots with
    prismatic, parallel and gimbal joints and a tree path."""
    from kincal.models.chain import Chain

    rng = np.random.default_rng(6)
    seen = 0
    for robot in sample_robots(tmp_path):
        for name in ("mdh", "complete"):
            try:
                model = models.build(name, robot.geometry)
            except Exception:  # a model that cannot describe this chain (a tree path)
                continue
            q = rng.uniform(-3.0, 3.0, (7, model.n))
            chain = Chain(model, q)
            for i in range(model.n):
                assert np.array_equal(chain._motion[i], chain.joint_motion(i, q[:, i]))
            for _ in range(20):
                x = model.nominal + rng.normal(size=model.size) * 10.0 ** rng.uniform(-8, 0)
                one = model.placements(x)
                rows = model.placements(np.stack([x, x + 1e-3]))[:, 0]  # the array path
                assert np.array_equal(one, rows) and np.array_equal(np.signbit(one),
                                                                    np.signbit(rows))
            seen += 1
    assert seen >= 4


def test_blas_is_limited_once_per_fit(monkeypatch):
    """A fit limits BLAS's threads once (solve's limit; the analysis inside it and a build
    without model auto do not enter threadpoolctl again), and the limit is in force in the
    analysis."""
    from threadpoolctl import threadpool_info

    from kincal.identification import blas_threads, reduction
    from kincal.planning.kind_simulation import simulate_points

    robot = Robot.load("ec66")
    model = models.build("mdh", robot.geometry)
    rng = np.random.default_rng(2)
    q = rng.uniform(-2.0, 2.0, (40, model.n))
    base, tool = np.array([1.0, 0.5, 0.2, 0.1, -0.2, 0.3]), np.array([0.03, 0.02, 0.12])
    data = simulate_points(model, model.nominal, base, tool, q, 5e-5, rng)
    controller = blas_threads._controller()
    entered, threads = [], []
    limit, analyze = controller.limit, reduction.analyze
    monkeypatch.setattr(controller, "limit", lambda **kw: entered.append(kw) or limit(**kw))

    def seen(*args, **kw):
        threads.append({lib["num_threads"] for lib in threadpool_info()
                        if lib["user_api"] == "blas"})
        return analyze(*args, **kw)

    monkeypatch.setattr(reduction, "analyze", seen)
    CalibrationProblem(robot, data, CalibrationOptions(method="ls")).solve()
    assert len(entered) == 1 and threads == [{1}]
