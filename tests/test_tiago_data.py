"""The real TIAGo motion-capture files of ../shared read correctly and fit sensibly.

The data live outside the repository (../shared/data/tiago_mocap, see its README) and
are never copied in; every test skips when they are absent. Quick: one frames-only fit.
"""

import warnings
from pathlib import Path

import numpy as np
import pytest

from kincal import CalibrationOptions, CalibrationProblem, Measurements, Robot

SHARED = Path(__file__).resolve().parents[2] / "shared"
DATA = SHARED / "data" / "tiago_mocap"
TRAIN = DATA / "qualisys_2021-11-30_static_postures.csv"
HELD_OUT = DATA / "qualisys_2021-11-26_static_postures.csv"
URDF = DATA / "tiago_48_schunk.urdf"
TIP = "wrist_ft_tool_link"
CHAIN = ("torso_lift_joint",) + tuple(f"arm_{i}_joint" for i in range(1, 8))
MARKER_1 = ("x1", "y1", "z1")
ROWS = {TRAIN: 37, HELD_OUT: 62}

pytestmark = pytest.mark.skipif(not all(p.is_file() for p in (TRAIN, HELD_OUT, URDF)),
                                reason=f"{DATA} is not present (shared data live outside the repo)")


@pytest.fixture(scope="module")
def robot():
    return Robot.load(URDF, tip=TIP)


def _read(robot, path, columns=MARKER_1):
    prismatic = [n for n, k in zip(robot.joint_names, robot.geometry.kinds) if k == "prismatic"]
    return Measurements.from_csv(path, robot.joint_names, prismatic=prismatic,
                                 position_columns=columns)


def test_chain_is_torso_and_seven_arm_joints_in_order(robot):
    assert robot.joint_names == CHAIN
    assert robot.geometry.kinds == ("prismatic",) + ("revolute",) * 7


@pytest.mark.parametrize("path", [TRAIN, HELD_OUT], ids=["training", "held_out"])
def test_sessions_read_through_from_csv(robot, path):
    data = _read(robot, path)
    assert len(data) == ROWS[path]
    assert data.joint_names == CHAIN
    assert data.joint_values.shape == (ROWS[path], 8) and data.positions.shape == (ROWS[path], 3)
    assert data.sigma is None  # the file has no "sigma" column; marker_std_mm is not one
    # positions in metres: the hand stays within a couple of metres of the mocap origin
    assert 0.05 < np.abs(data.positions).max() < 3.0
    # the torso lift is metres (0..0.35), the arm joints radians
    assert 0.0 <= data.joint_values[:, 0].min() and data.joint_values[:, 0].max() < 0.36
    assert np.abs(data.joint_values[:, 1:]).max() < 2 * np.pi
    # the first sample, straight from the text of the file
    header, first = (line.split(",") for line in path.read_text().splitlines()[:2])
    row = dict(zip(header, map(float, first)))
    np.testing.assert_array_equal(data.positions[0], [row[c] for c in MARKER_1])
    np.testing.assert_array_equal(data.joint_values[0], [row[j] for j in CHAIN])
    # every other column is reported as ignored, not silently used
    expected = tuple(h for h in header if h not in CHAIN + MARKER_1)
    assert data.ignored_columns == expected
    assert {"x2", "y4", "z4", "t_start_robot", "marker_std_mm"} <= set(data.ignored_columns)


def test_the_four_markers_form_one_rigid_body(robot):
    """Markers 2-4 read through position_columns too; their spacing never changes."""
    data = [_read(robot, TRAIN, (f"x{i}", f"y{i}", f"z{i}")) for i in range(1, 5)]
    spacing = np.linalg.norm(data[0].positions - data[2].positions, axis=1)
    assert np.ptp(spacing) < 1e-4 and 0.1 < spacing.mean() < 0.2  # ~166 mm, rigid


def test_frames_only_fit_matches_the_published_range(robot):
    """Nominal kinematics, measurement frame + marker point fitted: ~3.4 mm RMS.

    FIGAROH 1.0.2 reports 3.37 mm RMS / 5.55 mm max on the same file and model.
    """
    data = _read(robot, TRAIN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. a torso value 0.2 mm above its URDF limit
        result = CalibrationProblem(robot, data, CalibrationOptions(method="frames")).solve()
    assert len(result.identifiability.kept) == 9
    assert 3.2 < result.after.rms < 3.55 and 5.3 < result.after.max < 5.8
    # the marker is about (63, -3, 70) mm in the tip frame (README)
    np.testing.assert_allclose(result.tool * 1e3, [63, -3, 70], atol=10)
