"""``kincal compensate`` in blocks: the inverse kinematics of the targets block by block,
the output written piece by piece; the same numbers and the same text as in one piece."""

from __future__ import annotations

import numpy as np
import pytest

from kincal.compensation.targets import joint_scales
from kincal.compensation import ik
from kincal.compensation.compensate import Compensation
from kincal.errors import ExportError
from kincal.export.safe_write import write_all
from kincal.models import kinematics
from kincal.models.kinematics import ChainKinematics
from kincal.planning.simulation import random_rotation_near
from kincal.robot import Robot
from kincal.rotations import rotx


def _problem(n=50, seed=0):
    robot = Robot.load("ec66")
    g = robot.geometry
    chain = ChainKinematics.of(g)
    rng = np.random.default_rng(seed)
    q = rng.uniform(-1.0, 1.0, (n, g.n))
    R, p = chain.tool_poses(q, (0.0, 0.0, 0.12))
    seeds = q + rng.normal(size=q.shape) * 0.02
    rotations = np.array([random_rotation_near(R[k], 0.01, rng) for k in range(n)])
    required = rng.random(n) < 0.5
    return chain, p, rotations, required, seeds, g.lower, g.upper


def test_blocked_inverse_kinematics_equals_one_block(monkeypatch):
    chain, p, R, required, seeds, lo, hi = _problem()
    whole = ik.solve(chain, (0.0, 0.0, 0.12), p, R, required, seeds, lo, hi)
    assert whole.reached.mean() > 0.9
    monkeypatch.setattr(ik, "BLOCK", 7)
    monkeypatch.setattr(kinematics, "_ROWS", 5)
    blocked = ik.solve(chain, (0.0, 0.0, 0.12), p, R, required, seeds, lo, hi)
    for name in ("q", "position_error", "orientation_error", "reached", "at_limit",
                 "iterations"):
        np.testing.assert_array_equal(getattr(blocked, name), getattr(whole, name), name)


def test_targets_that_stall_are_stopped_early_and_the_others_are_untouched():
    # random joint values over the whole ranges, seeds 0.5 deg off, the seed's orientation
    # preferred: near singular wrists and limits some targets make no progress; the stall
    # rule stops them long before the iteration limit, with the same outcome (reached or
    # not), and every other target's numbers are those of the run without the rule
    robot = Robot.load("ec66")
    g = robot.geometry
    chain, tool = ChainKinematics.of(g), (0.02, 0.01, 0.12)
    rng = np.random.default_rng(0)
    q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), (1500, g.n))
    _, p = chain.tool_poses(q, tool)
    seeds = q + np.radians(0.5) * rng.normal(size=q.shape)
    R, _ = chain.tool_poses(seeds, tool)
    required = np.zeros(len(q), bool)
    rule = ik.solve(chain, tool, p, R, required, seeds, g.lower, g.upper)
    none = ik.solve(chain, tool, p, R, required, seeds, g.lower, g.upper,
                    ik.IkOptions(stall_window=100))  # a window as long as the limit: no rule
    limit = ik.IkOptions().max_iterations
    assert (none.iterations == limit).sum() >= 10  # the case has targets that never finish
    assert (rule.iterations < limit).all()
    stopped = rule.iterations < none.iterations
    assert stopped.sum() >= 10
    np.testing.assert_array_equal(rule.reached, none.reached)
    for name in ("q", "position_error", "orientation_error", "iterations"):
        np.testing.assert_array_equal(getattr(rule, name)[~stopped],
                                      getattr(none, name)[~stopped], name)


def test_blocked_tool_poses_and_evaluate_equal_one_block(monkeypatch):
    chain, *_ = _problem()
    q = np.random.default_rng(3).uniform(-3, 3, (23, chain.n))
    whole = chain.evaluate(q, (0.01, 0.0, 0.1))
    monkeypatch.setattr(kinematics, "_ROWS", 4)
    for a, b in zip(chain.evaluate(q, (0.01, 0.0, 0.1)), whole):
        np.testing.assert_array_equal(a, b)
    R, p = chain.tool_poses(q, (0.01, 0.0, 0.1))
    np.testing.assert_array_equal(R, whole[0])
    np.testing.assert_array_equal(p, whole[1])


def _old_text(c: Compensation, length_unit, angle_unit) -> str:
    """The CSV text as kincal wrote it before the output was written in blocks."""
    scale = joint_scales(c.kinds, length_unit, angle_unit)
    rows = [",".join(["target_line", *c.joint_names, "position_error_mm",
                      "orientation_error_deg", "reached"])]
    for k in range(len(c)):
        cells = [str(int(c.lines[k]))] + [repr(float(v)) for v in c.joint_values[k] / scale]
        cells += [f"{c.position_error[k] * 1e3:.6g}",
                  f"{np.degrees(c.orientation_error[k]):.6g}", str(int(c.reached[k]))]
        rows.append(",".join(cells))
    return "\n".join(rows) + "\n"


@pytest.mark.parametrize("units", [("m", "rad"), ("mm", "deg")])
def test_csv_blocks_are_the_text_as_before(units):
    rng = np.random.default_rng(1)
    n = 23
    q = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-8, 2, size=(n, 3))
    c = Compensation(("j1", "j2", "j3"), ("revolute", "prismatic", "revolute"), q, q * 1.001,
                     np.arange(n) + 2, np.abs(rng.normal(size=n)) * 1e-7,
                     np.abs(rng.normal(size=n)) * 1e-9, np.zeros(n, bool), rng.random(n) < 0.8,
                     np.zeros((n, 3), bool))
    expected = _old_text(c, *units)
    assert c.to_csv_text(*units) == expected
    assert "".join(c.csv_blocks(*units, rows=4)) == expected


def test_pieces_are_written_as_one_file(tmp_path):
    out = tmp_path / "o.csv"
    write_all([(out, (f"row {k}\n" for k in range(5)))])
    assert out.read_text() == "".join(f"row {k}\n" for k in range(5))


def test_a_failing_piece_leaves_nothing_behind(tmp_path):
    out = tmp_path / "o.csv"

    def pieces():
        yield "first\n"
        raise OSError(28, "No space left on device")

    with pytest.raises(ExportError, match="no output was written"):
        write_all([(out, pieces())])
    assert list(tmp_path.iterdir()) == []


def test_written_out_damped_pinv_is_the_inverse_formula():
    """The 3-row damped pseudo-inverse by its Cholesky factor written out equals
    A^T (A A^T + d2 I)^-1 through LAPACK's inverse, to 1e-14 times the condition number of
    A A^T + d2 I (both are that accurate): random tasks, tasks with columns of blocked
    joints set to zero, 7 joints, a large damping; other m take the inverse itself."""
    rng = np.random.default_rng(8)
    for n, d2 in ((6, 1e-12), (7, 1e-12), (6, 1e-2), (3, 1e-12)):
        A = rng.normal(size=(200, 3, n))
        A[:50, :, rng.integers(n)] = 0.0
        At = np.swapaxes(A, 1, 2)
        M = A @ At + d2 * np.eye(3)
        want = At @ np.linalg.inv(M)
        got = kinematics.damped_pinv(A, d2)
        assert got.shape == want.shape
        err = np.abs(got - want).max(axis=(1, 2)) / np.abs(want).max(axis=(1, 2))
        assert np.all(err <= 1e-14 * np.linalg.cond(M))
        assert np.median(err) < 1e-13
    A = rng.normal(size=(20, 6, 6))
    want = np.swapaxes(A, 1, 2) @ np.linalg.inv(A @ np.swapaxes(A, 1, 2) + 1e-6 * np.eye(6))
    assert np.array_equal(kinematics.damped_pinv(A, 1e-6), want)


def test_step_through_the_projector_factors_is_the_projector_step():
    """The prioritised step with the null-space projector applied through its factors
    equals the step with I - Jp^+ Jp made, to 1e-10 of the step where the orientation
    task in the null space is well conditioned (most rows)."""
    chain, p, rotations, required, seeds, lower, upper = _problem(200, seed=3)
    _, p0, Jp, Jo = chain.evaluate(seeds, (0.0, 0.0, 0.12))
    rng = np.random.default_rng(2)
    e_p, e_o = p - p0, rng.normal(size=(200, 3)) * 0.01
    Jp[:40, :, 4] = 0.0  # a blocked joint
    Jo[:40, :, 4] = 0.0
    d2 = 1e-12
    pinv = lambda A: np.swapaxes(A, 1, 2) @ np.linalg.inv(  # noqa: E731
        A @ np.swapaxes(A, 1, 2) + d2 * np.eye(3))
    P = pinv(Jp)
    dq1 = np.einsum("kij,kj->ki", P, e_p)
    null = np.eye(6) - P @ Jp
    dq2 = np.einsum("kij,kj->ki", pinv(Jo @ null), e_o - np.einsum("kij,kj->ki", Jo, dq1))
    want = dq1 + np.einsum("kij,kj->ki", null, dq2)
    got = ik._step(Jp, Jo, e_p, e_o, 1e-6)
    B = Jo @ null
    fine = np.linalg.cond(B @ np.swapaxes(B, 1, 2) + d2 * np.eye(3)) < 1e6
    assert fine.sum() > 150
    err = np.abs(got - want).max(axis=1) / np.abs(want).max(axis=1)
    assert err[fine].max() <= 1e-10
