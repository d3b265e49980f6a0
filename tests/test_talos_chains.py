"""TALOS, two arms as two chains from the two soles sharing the torso: the one corrected
URDF through Pinocchio, and the command line of issue 18 on the real left-gripper touches
with simulated right-gripper ones."""

import warnings

import numpy as np
import pytest

from kincal.cli.main import main
from kincal.frames_file import CellFrames
from kincal.identification.chains import Chains
from kincal.models.chain import Chain
from kincal.robot import Robot


def _q(robot, n, rng):
    g = robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    return rng.uniform(0.8 * lo, 0.8 * hi, (n, g.n))


def test_talos_two_arms_one_corrected_urdf(tmp_path):
    """TALOS standing on both soles, each arm its chain: the torso's origins once in the
    union; the corrected URDF is the one original file with every traversed origin
    corrected, and Pinocchio reloads each chain from it as the chain models predict
    (< 1e-12 m, rad)."""
    from kincal.descriptions import erd_robots_dir
    from kincal.export.readable_export import corrected_text

    root = erd_robots_dir()
    path = None if root is None else root / "talos_data" / "robots" / "talos_full_v2.urdf"
    if path is None or not path.exists():
        pytest.skip("example-robot-data's TALOS is not installed")
    arms = [Robot.load(path, base=f"{s}_sole_link", tip=f"gripper_{s}_base_link")
            for s in ("left", "right")]
    ch = Chains(arms, 2)
    assert sum(n.startswith("torso_2_joint.") for n in ch.model.names) == 6
    rng = np.random.default_rng(0)
    kin = rng.normal(0, 5e-3, ch.model.size)  # 5 mm, 0.3 deg on every origin
    edits, _ = corrected_text(arms[0], arms[0].with_origins(ch.origins(kin)), readable=False,
                              joints=ch.model.joint_names)
    assert {e.joint for e in edits.edits if e.changed} == set(ch.model.joint_names)
    out = tmp_path / "talos_cal.urdf"
    out.write_text(edits.text)
    for k, arm in enumerate(arms):
        back = Robot.load(out, base=arm.base, tip=arm.tip)
        q = _q(arm, 20, rng)
        s = Chain(ch.models[k], q).state(kin[ch.idx[k]], None, keep=False)
        T = back.tip_poses(q)
        assert np.abs(T[:, :3, 3] - s.p_tip).max() < 1e-12
        assert np.abs(T[:, :3, :3] - s.R_tip).max() < 1e-12


TALOS_DATA = "/work/shared/data/talos_contact"


def test_talos_two_arms_command_line_smoke(tmp_path, capsys):
    """The interface of issue 18 on TALOS: the real left-gripper touches and simulated
    right-gripper touches (nominal robot, inverse kinematics onto a table), two chains from
    the two soles sharing the torso (--lambda evidence to keep it quick); the one corrected
    URDF reloads for both chains, FRAMES.json records each set's chain, and the left
    held-out touches of another day come out better than nominal."""
    import csv
    from pathlib import Path

    from kincal.descriptions import erd_robots_dir
    from kincal.rotations import tilt_angles
    from kincal.measurements.plane import fit_plane
    from kincal.rotations import rotx, roty

    root = erd_robots_dir()
    urdf = None if root is None else root / "talos_data" / "robots" / "talos_full_v2.urdf"
    if urdf is None or not urdf.exists() or not Path(TALOS_DATA).exists():
        pytest.skip("TALOS (example-robot-data) or the shared TALOS data are not here")
    names = next(csv.reader(open(f"{TALOS_DATA}/left_train.csv")))[5:]

    def joints(name):  # the 5 metadata fields dropped, by position (module README)
        return np.array([[float(v) for v in r[5:]] for r in csv.reader(open(
            f"{TALOS_DATA}/{name}")) if r and r[0] == "gripper"])

    def write(path, rows):
        path.write_text(",".join(names) + "\n" + "".join(
            ",".join(repr(float(v)) for v in row) + "\n" for row in rows))
        return str(path)

    train, valid = joints("left_train.csv"), joints("left_validation.csv")
    left = write(tmp_path / "LEFT.csv", train)
    arm = Robot.load(urdf, base="right_sole_link", tip="gripper_right_base_link")
    rng = np.random.default_rng(0)
    tool = np.array([0.0, 0.0, -0.12])
    rows = []
    while len(rows) < 21:
        p = np.r_[0.45 + rng.uniform(-0.1, 0.1), -0.25 + rng.uniform(-0.1, 0.1), 0.75]
        c, s = np.cos(rng.uniform(-0.4, 0.4)), np.sin(rng.uniform(-0.4, 0.4))
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.diag([1.0, -1.0, -1.0])
        q, ok = arm.inverse_kinematics(p, tool, R, start=rng.normal(0, 0.2, arm.geometry.n))
        if ok and np.all((q >= arm.geometry.lower) & (q <= arm.geometry.upper)):
            row = train[0].copy()
            row[[names.index(j) for j in arm.joint_names]] = q
            rows.append(row)
    right = write(tmp_path / "RIGHT.csv", rows)
    out, frames = tmp_path / "CAL.urdf", tmp_path / "FRAMES.json"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["calibrate", str(urdf), left, right, "--base", "left_sole_link",
                     "right_sole_link", "--tip", "gripper_left_base_link",
                     "gripper_right_base_link", "--on-plane", "--flush", "--tool-offset", "0",
                     "0", "-0.12", "--out", str(out), "--frames-out",
                     str(frames), "--quiet"]) == 0
    f = CellFrames.read(frames)
    assert [(s.base_frame, s.tip_frame) for s in f.sets] == [
        ("left_sole_link", "gripper_left_base_link"), ("right_sole_link", "gripper_right_base_link")]
    s = f.sets[0]

    def held_out(robot, t, tilts):
        """left validation RMS: height [mm], roll and pitch [deg]; plane fitted to train."""
        def frame(Q):
            T = robot.tip_poses(Q[:, [names.index(j) for j in robot.joint_names]])
            return T[:, :3, 3] + T[:, :3, :3] @ t, T[:, :3, :3] @ rotx(tilts[0]) @ roty(tilts[1])
        Pt, At = frame(train)
        n, d, _ = fit_plane(Pt)
        if np.mean(At[:, :, 2] @ n) < 0:
            n, d = -n, -d
        Pv, Av = frame(valid)
        a, b = tilt_angles(np.einsum("nji,j->ni", Av, n))
        rms = lambda v: float(np.sqrt(np.mean(np.square(v))))  # noqa: E731
        return rms(Pv @ n - d) * 1e3, np.degrees(rms(a)), np.degrees(rms(b))

    nominal = held_out(Robot.load(urdf, base="left_sole_link", tip="gripper_left_base_link"),
                       tool, (0.0, 0.0))
    after = held_out(Robot.load(out, base="left_sole_link", tip="gripper_left_base_link"),
                     np.array([s.value("tool." + c) for c in "xyz"]),
                     (s.value("tool.rx"), s.value("tool.ry")))
    print("left held-out: nominal %.2f mm %.2f %.2f deg" % nominal,
          "| two chains %.2f mm %.2f %.2f deg" % after)
    assert after[0] < nominal[0] and after[1] < nominal[1] and after[2] < nominal[2]
