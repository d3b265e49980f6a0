"""The one writer's read-back of the corrected URDF (kincal.export.readback): the honest text
passes, also with added frames and with offsets the readable export moves into child
origins; a planted corruption of any other part of the file, or a wrong or non-finite
origin, is refused and nothing is written; and yourdfpy, a third URDF reader, reads the
written file as the calibrated model."""

import io
import re
import warnings

import numpy as np
import pytest
import yourdfpy
from conftest import random_joint_values, tiago_urdf

from kincal import Measurements, Robot, calibrate
from kincal.cli import main
from kincal.errors import ExportError
from kincal.export import outputs
from kincal.export.outputs import Outputs, write_calibration


def _quiet(fn, *args, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(*args, **kw)


@pytest.fixture(scope="module")
def ec66_result(tmp_path_factory):
    path = tmp_path_factory.mktemp("readback") / "p.csv"
    assert main(["simulate", "ec66", "--poses", "40", "--out", str(path), "--seed", "3",
                 "--quiet"]) == 0
    robot = Robot.load("ec66")
    return _quiet(calibrate, robot, Measurements.from_csv(path, robot.joint_names), method="ls")


def _yourdfpy_tip_poses(text, robot, q):
    u = yourdfpy.URDF.load(io.BytesIO(text.encode("utf-8")), load_meshes=False,
                           build_collision_scene_graph=False, load_collision_meshes=False)
    out = np.empty((len(q), 4, 4))
    for k, qk in enumerate(q):
        u.update_cfg(dict(zip(robot.joint_names, qk)))
        out[k] = u.get_transform(frame_to=robot.tip, frame_from=robot.base)
    return out


def test_the_written_file_is_the_calibrated_model_to_yourdfpy(ec66_result, tmp_path, rng):
    out = tmp_path / "c.urdf"
    write_calibration(ec66_result, Outputs(urdf=out, add_frames=True))
    text = out.read_text()
    assert "kincal_tool_point" in text and "kincal_measurement_frame" in text
    robot = ec66_result.corrected
    q = random_joint_values(robot.geometry, rng, 50)
    assert np.abs(_yourdfpy_tip_poses(text, robot, q) - robot.tip_poses(q)).max() < 1e-12


def _planted(monkeypatch, change):
    honest = outputs._corrected  # what write_calibration writes (text, notes, folds)

    def corrupted(result, readable=True, add_frames=False, no_fold=None):
        text, notes, made = honest(result, readable, add_frames, no_fold)
        bad = change(text)
        assert bad != text  # the corruption did land
        return bad, notes, made

    monkeypatch.setattr(outputs, "_corrected", corrupted)


def _sub(pattern, repl):
    return lambda text: re.sub(pattern, repl, text, count=1, flags=re.S)


CORRUPTIONS = {
    # an attribute of a calibrated joint other than its origin
    "joint limit": (_sub(r'(<joint name="joint_2".*?<limit[^>]*effort=")[^"]*', r"\g<1>151"),
                    "joint_2.*'effort'"),
    # a link
    "link mass": (_sub(r'(<link name="link_3".*?<mass value=")[^"]*', r"\g<1>2.6"),
                  "link_3.*'value'"),
    "link name": (_sub(r'<link name="link_3"', '<link name="link_3b"'), "link_3"),
    # an origin that is not a finite number
    "NaN origin": (_sub(r'(<joint name="joint_4".*?<origin[^>]*xyz=")[^ ]*', r"\g<1>nan"),
                   "joint_4.*finite"),
    # an origin a micrometre off the calibration
    "nudged origin": (lambda t: re.sub(
        r'(<joint name="joint_3".*?<origin[^>]*xyz=")([-0-9.e]+)',
        lambda m: m.group(1) + repr(float(m.group(2)) + 1e-6), t, count=1, flags=re.S),
        "joint_3.*from its corrected placement"),
    # a joint off the calibrated chain
    "fixed joint origin": (_sub(r'(<joint name="flange_joint".*?<origin[^>]*xyz=")[^"]*',
                                r"\g<1>0 0 0.2"), "flange_joint.*'xyz'"),
    # an element added without add_frames, and one removed
    "added link": (_sub(r"</robot>", '<link name="kincal_extra"/></robot>'), "kincal_extra"),
    "removed joint": (_sub(r'<joint name="flange_joint".*?</joint>', ""), "elements"),
    # another attribute added to an origin
    "origin attribute": (_sub(r'(<joint name="joint_5".*?<origin)', r'\g<1> scale="2"'),
                         "joint_5.*'scale'"),
}


@pytest.mark.parametrize("case", sorted(CORRUPTIONS))
def test_a_planted_corruption_is_refused_and_nothing_written(ec66_result, tmp_path,
                                                            monkeypatch, case):
    change, message = CORRUPTIONS[case]
    _planted(monkeypatch, change)
    urdf, frames = tmp_path / "c.urdf", tmp_path / "f.json"
    with pytest.raises(ExportError, match="read back before writing.*" + message):
        write_calibration(ec66_result, Outputs(urdf=urdf, frames=frames))
    assert not urdf.exists() and not frames.exists()


def test_an_offset_moved_into_child_origins_passes(tmp_path, rng):
    """TIAGo's arm_6 origin sits at pitch -90 deg: the readable export writes its offset into
    arm_7's origin (kincal.export.readable_export); the check accepts that exact text."""
    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure

    robot = Robot.load(tiago_urdf(), tip="wrist_ft_tool_link")
    model = mdh.extract(robot.geometry)
    table = model.table.copy()
    table[:, 3] += rng.normal(size=len(table)) * 2e-3  # joint offsets
    q = random_joint_values(robot.geometry, rng, 80) * 0.8
    data = measure(model, Truth(table, np.zeros(6), np.array([0.0, 0.0, 0.1])), q, 1e-6, rng)
    result = _quiet(calibrate, robot, data, method="ls", model="offsets")
    out = tmp_path / "c.urdf"
    assert result.plausibility.plausible
    written = write_calibration(result, Outputs(urdf=out))
    assert any("arm_6_joint" in n and "origins of arm_7_joint" in n for n in written.notes)
    q = random_joint_values(robot.geometry, rng, 50)
    assert np.abs(Robot.load(out, tip=robot.tip).tip_poses(q)
                  - result.corrected.tip_poses(q)).max() < 1e-12


def test_an_origin_added_to_a_joint_that_had_none_passes(tmp_path, rng):
    """A calibrated joint without <origin> (identity) gets one written: accepted, and the
    written file is the calibrated model."""
    from pathlib import Path

    from kincal.models import mdh
    from kincal.planning.simulation import Truth, measure

    text = (Path(__file__).parents[1] / "urdf" / "ec66.urdf").read_text()
    bare = re.sub(r'(<joint name="joint_4".*?)<origin[^>]*/>', r"\1", text, count=1, flags=re.S)
    assert bare != text
    path = tmp_path / "bare.urdf"
    path.write_text(bare)
    robot = Robot.load(path, tip="flange")
    model = mdh.extract(robot.geometry)
    q = rng.uniform(-2, 2, (60, 6))
    truth = Truth(model.table + rng.normal(size=model.table.shape) * 3e-4,
                  np.array([0.8, 0.3, -0.2, 0.02, -0.03, 1.2]), np.array([0.02, 0.01, 0.12]))
    result = _quiet(calibrate, robot, measure(model, truth, q, 1e-6, rng), method="ls")
    out = tmp_path / "c.urdf"
    write_calibration(result, Outputs(urdf=out))
    joint = re.search(r'<joint name="joint_4".*?</joint>', out.read_text(), re.S).group(0)
    assert "<origin" in joint
    q = random_joint_values(robot.geometry, rng, 50)
    assert np.abs(Robot.load(out, tip="flange").tip_poses(q)
                  - result.corrected.tip_poses(q)).max() < 1e-12


def test_a_urdf_with_a_default_namespace_is_calibrated_and_its_mimics_read(tmp_path):
    """Drake's URDFs declare xmlns="http://drake.mit.edu" on <robot>, which urdfdom ignores:
    the read-back check saw '{http://drake.mit.edu}joint', compared the chain's joints as
    other elements and refused every calibration ("please report this"); the mimic tags of
    such a file were not seen."""
    text = Robot.load("ec66").urdf_text
    ns = text.replace('<robot name="ec66"', '<robot name="ec66" xmlns="http://drake.mit.edu"')
    assert ns != text
    (tmp_path / "plain.urdf").write_text(text)
    (tmp_path / "ns.urdf").write_text(ns)
    assert main(["simulate", "ec66", "--poses", "30", "--out", str(tmp_path / "d.csv"),
                 "--seed", "3", "--quiet"]) == 0
    for name in ("plain", "ns"):
        assert main(["calibrate", str(tmp_path / f"{name}.urdf"), str(tmp_path / "d.csv"),
                     "--tip", "flange", "--lambda", "0.01", "--model", "complete",
                     "--out", str(tmp_path / f"{name}_cal.urdf"), "--quiet"]) == 0
    origins = [re.findall(r"<origin [^>]*>", (tmp_path / f"{name}_cal.urdf").read_text())
               for name in ("plain", "ns")]
    assert len(origins[0]) == 14 and origins[0] == origins[1]  # the same corrected origins
    mimic = ns.replace('<joint name="joint_6" type="revolute">',
                       '<joint name="joint_6" type="revolute"><mimic joint="joint_5" '
                       'multiplier="2" offset="0.5"/>')
    (tmp_path / "mimic.urdf").write_text(mimic)
    assert Robot.load(tmp_path / "mimic.urdf", tip="flange").mimics == {
        "joint_6": ("joint_5", 2.0, 0.5)}
