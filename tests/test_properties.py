"""Property-based tests (hypothesis) on random serial chains and random data."""

import math

import numpy as np
from chains import CASES, random_chain
from conftest import random_joint_values
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kincal.export.urdf_export import edit_joint_origins
from kincal.measurements.data import Measurements
from kincal.measurements.point import MeasurementModel
from kincal.models import mdh
from kincal.robot import Robot
from kincal.rotations import matrix_to_rpy, rpy_to_matrix

SETTINGS = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7),
       cases=st.lists(st.sampled_from(CASES), min_size=1, max_size=4, unique=True),
       scale=st.sampled_from([0.0, 1e-6, 1e-3, 3e-2]))
def test_parameter_layer_and_export_round_trip(tmp_path_factory, seed, n, cases, scale):
    rng = np.random.default_rng(seed)
    text, _ = random_chain(rng, n=n, cases=tuple(cases))
    path = tmp_path_factory.mktemp("chain") / "chain.urdf"
    path.write_text(text)
    robot = Robot.load(path, tip="tip")
    model = mdh.extract(robot.geometry)
    table = model.table + rng.normal(size=model.table.shape) * scale
    corrected = robot.with_joint_frames(model.joint_frames(table))
    q = random_joint_values(robot.geometry, rng, 50)
    R, p = MeasurementModel(model, q).tip_poses(table)
    T = corrected.tip_poses(q)
    assert np.abs(T[:, :3, 3] - p).max() < 1e-12 and np.abs(T[:, :3, :3] - R).max() < 1e-12
    out = edit_joint_origins(robot.urdf_text, robot.changed_origins(corrected)).text
    if scale == 0.0:
        assert out == robot.urdf_text
    path2 = path.with_name("corrected.urdf")
    path2.write_text(out)
    T2 = Robot.load(path2, tip="tip").tip_poses(q)
    assert np.abs(T2 - T).max() < 1e-12


angles = st.floats(-10.0, 10.0, allow_nan=False)


@SETTINGS
@given(r=angles, p=angles, y=angles, near_lock=st.booleans(), eps=st.floats(-1e-3, 1e-3),
       dr=st.floats(-1e-3, 1e-3), dp=st.floats(-1e-3, 1e-3), dy=st.floats(-1e-3, 1e-3))
def test_rpy_is_exact_and_stays_near_its_reference(r, p, y, near_lock, eps, dr, dp, dy):
    if near_lock:
        p = math.copysign(math.pi / 2, p) + eps
    ref = np.array([r, p, y])
    R = rpy_to_matrix(ref)
    got = matrix_to_rpy(R, near=ref)
    assert np.abs(rpy_to_matrix(got) - R).max() < 1e-14
    assert np.abs(got - ref).max() < 1e-6 or near_lock  # unchanged rotation, same numbers
    # a small change of the triple itself is found again, away from gimbal lock
    moved = ref + [dr, dp, dy]
    got = matrix_to_rpy(rpy_to_matrix(moved), near=ref)
    assert np.abs(rpy_to_matrix(got) - rpy_to_matrix(moved)).max() < 1e-14
    if abs(math.cos(p)) > 0.1:
        assert np.abs(got - moved).max() < 1e-9


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 40), with_sigma=st.booleans())
def test_csv_round_trip_is_exact(tmp_path_factory, seed, n, with_sigma):
    rng = np.random.default_rng(seed)
    names = ("j1", "j2", "j3")
    q = rng.normal(size=(n, 3)) * 10 ** rng.uniform(-12, 1)
    P = rng.normal(size=(n, 3)) * 10 ** rng.uniform(-9, 2)
    sigma = rng.uniform(1e-6, 1e-3, n) if with_sigma else None
    data = Measurements(names, q, P, sigma)
    path = tmp_path_factory.mktemp("csv") / "d.csv"
    path.write_text(data.to_csv_text())
    back = Measurements.from_csv(path, names)
    assert np.array_equal(back.joint_values, q) and np.array_equal(back.positions, P)
    assert (back.sigma is None) == (sigma is None)
    if sigma is not None:
        assert np.array_equal(back.sigma, sigma)


@SETTINGS
@given(rx=angles, ry=angles, rz=angles, lock=st.sampled_from([None, 1.0, -1.0]))
def test_measurement_frame_angles_give_the_rotation_back(rx, ry, rz, lock):
    """kincal.rotations.base_angles, the start of every measurement and tool frame (point and
    pose sets) and the rpy-xyz orientation columns, gives the angles of R = Rx Ry Rz back,
    also at exact gimbal lock (ry = +-90 deg: R's first row and last column (0 0 +-1)),
    where its former yaw from R's first row read atan2(0, 0) = 0 whatever the rotation."""
    from kincal.measurements.orientation_columns import orientation_values, rotations
    from kincal.rotations import base_angles, base_rotation, rotx, rotz

    R = base_rotation(rx, ry, rz)
    if lock is not None:  # R = Rx(rx) Ry(+-90 deg) Rz(rz) with its exact zeros
        R = rotx(rx) @ np.array([[0.0, 0.0, lock], [0.0, 1.0, 0.0], [-lock, 0.0, 0.0]]) @ rotz(rz)
        R[0, :2] = R[1:, 2] = 0.0
    a = base_angles(R)
    assert np.abs(base_rotation(*a) - R).max() < 1e-14
    assert -math.pi / 2 <= a[1] <= math.pi / 2
    b = orientation_values(R[None], "rpy-xyz")  # the columns: these angles, for a stack
    assert np.abs(b[0] - a).max() < 1e-14 and np.abs(rotations(b, "rpy-xyz")[0] - R).max() < 1e-14
    if lock is None and abs(math.cos(a[1])) > 1e-3:  # intrinsic x-y-z, away from the lock
        from scipy.spatial.transform import Rotation

        d = Rotation.from_matrix(R).as_euler("XYZ") - a
        assert np.abs((d + math.pi) % (2 * math.pi) - math.pi).max() < 1e-12  # up to 2 pi
