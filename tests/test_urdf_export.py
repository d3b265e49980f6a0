"""Corrected joint origins written into the user's URDF text, and nothing else changed.

Every edited file is read back by two independent URDF readers (Pinocchio, through
urdfdom, and yourdfpy, through lxml + trimesh) to check the placements to 1e-12.
"""

from __future__ import annotations

import difflib
import io
import os
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from conftest import ur10_path
from lxml import etree
from scipy.spatial.transform import Rotation

from kincal.errors import ExportError, FrameError, UrdfError
from kincal.export.safe_write import write_text_atomic
from kincal.export.urdf_export import add_fixed_frame, edit_joint_origins
from kincal.rotations import (
    rotx,
    rotz,
    transform,
    xyz_rpy_to_transform,
)
from kincal.urdf_source import check_urdf_text

REPO = Path(__file__).resolve().parents[1]
EC66 = REPO / "urdf" / "ec66.urdf"
TIAGO = Path(__file__).resolve().parents[2] / "shared/data/tiago_mocap/tiago_48_schunk.urdf"
TOL = 1e-12


def robot_path(name: str) -> Path:
    if name == "ec66":
        return EC66
    if name == "ur10":
        return ur10_path()
    if not TIAGO.exists():
        pytest.skip(f"{TIAGO} not present")
    return TIAGO


@pytest.fixture(params=["ec66", "ur10", "tiago"])
def robot(request) -> tuple[str, str]:
    return request.param, robot_path(request.param).read_bytes().decode("utf-8")


@dataclass(frozen=True)
class Joint:
    type: str
    parent: str
    T: np.ndarray  # original origin, T_parentlink_joint
    rpy: tuple
    origin_line: int | None  # 1-based line of its <origin>


def joints_of(text: str) -> dict[str, Joint]:
    """Top-level joints as an independent reader (lxml) sees them."""
    joints = {}
    for j in etree.fromstring(text.encode()).iterchildren("joint"):
        origin = j.find("origin")
        attrs = origin.attrib if origin is not None else {}
        xyz = [float(v) for v in attrs.get("xyz", "0 0 0").split()]
        rpy = tuple(float(v) for v in attrs.get("rpy", "0 0 0").split())
        joints[j.get("name")] = Joint(j.get("type"), j.find("parent").get("link"),
                                      xyz_rpy_to_transform(xyz, rpy), rpy,
                                      origin.sourceline if origin is not None else None)
    return joints


def pin_origins(text: str, names) -> dict[str, np.ndarray]:
    """T_parentlink_joint as Pinocchio reads it, from frames at the neutral configuration."""
    model = pin.buildModelFromXML(text)
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    joints = joints_of(text)
    out = {}
    for name in names:
        f_joint = model.getFrameId(name)
        f_parent = model.getFrameId(joints[name].parent, pin.BODY)
        assert model.frames[f_joint].name == name and f_parent < len(model.frames)
        out[name] = (data.oMf[f_parent].inverse() * data.oMf[f_joint]).homogeneous
    return out


def yourdfpy_origins(text: str, names) -> dict[str, np.ndarray]:
    urdf = yourdfpy.URDF.load(io.BytesIO(text.encode()), build_scene_graph=False, load_meshes=False,
                              build_collision_scene_graph=False, load_collision_meshes=False)
    return {name: urdf.joint_map[name].origin for name in names}


def assert_reloads_as(text: str, origins: dict) -> None:
    for reader in (pin_origins, yourdfpy_origins):
        got = reader(text, origins)
        for name, T in origins.items():
            err = np.max(np.abs(got[name] - T))
            assert err < TOL, f"{reader.__name__}: {name} off by {err:.2e}"


def rng_for(*key) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(repr(key).encode()))


def random_origins(joints: dict[str, Joint], names, rng, scale: str) -> dict[str, np.ndarray]:
    origins = {}
    for name in names:
        if scale == "small":  # a calibration-sized correction of the nominal origin
            dT = transform(Rotation.from_rotvec(rng.normal(size=3) * 1e-3).as_matrix(), rng.normal(size=3) * 1e-3)
            origins[name] = joints[name].T @ dT
        else:
            origins[name] = transform(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-1, 1, 3))
    return origins


# ---------------------------------------------------------------- round trips


@pytest.mark.parametrize("scale", ["small", "large"])
def test_random_origins_reload_exactly(robot, scale):
    name, text = robot
    joints = joints_of(text)
    movable = [j for j, info in joints.items() if info.type != "fixed"]
    assert len(movable) >= 6
    origins = random_origins(joints, movable, rng_for(name, scale), scale)
    result = edit_joint_origins(text, origins)
    assert [e.joint for e in result.edits] == movable
    assert all(e.changed for e in result.edits)
    assert_reloads_as(result.text, origins)


def test_fixed_joints_too(robot):
    name, text = robot
    joints = joints_of(text)
    fixed = [j for j, info in joints.items() if info.type == "fixed"]
    if not fixed:
        pytest.skip(f"{name} has no fixed joint")
    origins = random_origins(joints, fixed, rng_for(name, "fixed"), "large")
    assert_reloads_as(edit_joint_origins(text, origins).text, origins)


@pytest.mark.parametrize("pitch", [np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-9, -np.pi / 2 + 1e-6, 1.57079632679])
def test_gimbal_lock_rotations_reload_exactly(pitch):
    text = EC66.read_text()
    rng = rng_for("gimbal", pitch)
    origins = {f"joint_{i}": xyz_rpy_to_transform(rng.uniform(-1, 1, 3), (rng.uniform(-3, 3), pitch, rng.uniform(-3, 3)))
               for i in range(1, 7)}
    assert_reloads_as(edit_joint_origins(text, origins).text, origins)


def test_tiago_near_gimbal_lock_origins():
    """arm_4..arm_6 have pitch -1.57079632679: corrections must still reload exactly."""
    text = robot_path("tiago").read_text()
    joints = joints_of(text)
    names = ["arm_4_joint", "arm_5_joint", "arm_6_joint"]
    assert all(abs(abs(joints[n].rpy[1]) - np.pi / 2) < 1e-11 for n in names)
    rng = rng_for("tiago-gimbal")
    for angle in (1e-9, 1e-6, 1e-3, 0.3):
        origins = {n: joints[n].T @ transform(Rotation.from_rotvec(rng.normal(size=3) * angle).as_matrix())
                   for n in names}
        result = edit_joint_origins(text, origins)
        assert all(e.new_xyz == e.old_xyz for e in result.edits)  # rotation only: xyz text kept
        assert_reloads_as(result.text, origins)


# ---------------------------------------------------------------- preservation


def stripped_tree(text: str) -> bytes:
    """The whole document with the xyz/rpy of top-level-joint origins removed."""
    root = etree.fromstring(text.encode())
    for origin in root.xpath("/robot/joint/origin"):
        for key in ("xyz", "rpy"):
            origin.attrib.pop(key, None)
    return etree.tostring(root.getroottree())  # tags, attributes in order, text, tails, comments


def test_everything_but_edited_origins_is_preserved(robot):
    name, text = robot
    joints = joints_of(text)
    movable = [j for j, info in joints.items() if info.type != "fixed"]
    result = edit_joint_origins(text, random_origins(joints, movable, rng_for(name, "keep"), "large"))
    new = result.text

    def comments(t):
        return len(etree.fromstring(t.encode()).getroottree().xpath("//comment()"))

    assert comments(new) == comments(text) == text.count("<!--") > 0
    assert stripped_tree(new) == stripped_tree(text)
    assert stripped_tree(new) != stripped_tree(text.replace("<!--", "<!-- x", 1))  # the comparison can fail

    old_lines, new_lines = text.splitlines(keepends=True), new.splitlines(keepends=True)
    changed = set()
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(None, old_lines, new_lines, autojunk=False).get_opcodes():
        if tag != "equal":
            assert tag == "replace" and i2 - i1 == j2 - j1, (tag, old_lines[i1:i2], new_lines[j1:j2])
            changed.update(range(i1 + 1, i2 + 1))
    assert changed == {joints[e.joint].origin_line for e in result.edits if e.changed}
    for line in changed:
        assert new_lines[line - 1].lstrip().startswith("<origin ")


def test_unchanged_origin_keeps_its_text(robot):
    name, text = robot
    joints = joints_of(text)
    result = edit_joint_origins(text, {j: info.T for j, info in joints.items()})
    assert result.text == text
    assert not any(e.changed for e in result.edits)
    assert all(np.all(e.rpy_change == 0) for e in result.edits)


def test_rotation_rebuilt_via_quaternion_keeps_rpy_text(robot):
    """A rotation equal to a few ulps (as another library rebuilds it) is no reason to rewrite rpy."""
    name, text = robot
    joints = joints_of(text)
    origins = {}
    for j, info in joints.items():
        T = info.T.copy()
        T[:3, :3] = Rotation.from_euler("xyz", info.rpy).as_matrix()  # extrinsic xyz = Rz Ry Rx
        origins[j] = T
    assert max(np.max(np.abs(origins[j] - info.T)) for j, info in joints.items()) > 0  # not trivially equal
    assert edit_joint_origins(text, origins).text == text


def test_small_rotation_gives_close_rpy(robot):
    name, text = robot
    joints = joints_of(text)
    far = [j for j, info in joints.items() if abs(np.cos(info.rpy[1])) > 0.1]
    rng = rng_for(name, "close")
    angle = 1e-4
    origins = {}
    for j in far:
        axis = rng.normal(size=3)
        origins[j] = joints[j].T @ transform(Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix())
    result = edit_joint_origins(text, origins)
    for edit in result.edits:
        assert 0 < np.linalg.norm(edit.rpy_change) < 10 * angle, edit
        assert edit.new_xyz == edit.old_xyz


# ---------------------------------------------------------------- exact text on a file full of traps

TRAPS = """<?xml version='1.0' encoding='utf-8'?>
<!-- a robot full of traps: Gelenk ä, ✓ -->
<robot name='traps' xmlns:xacro="http://www.ros.org/wiki/xacro">
  <link name='base'/>
  <link name="arm"/>
  <link name="tool"/>
  <!-- <joint name="shoulder" type="revolute"><origin xyz="9 9 9" rpy="0 0 0"/></joint> -->
  <joint name='shoulder' type='revolute'>
    <parent link='base'/>
    <child link='arm'/>
    <dynamics damping="0.1"><origin xyz="5 5 5"/></dynamics>
    <origin xyz='0  0\t0.1' rpy='0  0 0'/>
    <axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
  </joint>
  <joint name="wrist" type="fixed">
    <parent link="arm"/>
    <child link="tool"/>
  </joint>
  <transmission name="t">
    <type>transmission_interface/SimpleTransmission</type>
    <joint name="shoulder"><origin xyz="7 7 7"/><hardwareInterface>x</hardwareInterface></joint>
  </transmission>
  <gazebo reference="shoulder">
    <joint name="wrist"><origin xyz="8 8 8" rpy="1 1 1"/></joint>
  </gazebo>
  <gazebo><![CDATA[<joint name="wrist"><origin xyz="6 6 6"/></joint>]]></gazebo>
</robot>
"""
# urdfdom (hence Pinocchio) splits numbers on single spaces only, so the tab in xyz
# makes this file unreadable to Pinocchio until xyz is rewritten; double spaces are fine
SHOULDER = "<origin xyz='0  0\t0.1' rpy='0  0 0'/>"


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_only_the_real_origins_change(newline):
    text = TRAPS.replace("\n", newline)
    origins = {"shoulder": transform(None, [0.0, 0.0, 0.25]), "wrist": transform(rotz(0.5), [0.1, 0.0, 0.0])}
    result = edit_joint_origins(text, origins)
    expected = text.replace(SHOULDER, "<origin xyz='0 0 0.25' rpy='0  0 0'/>").replace(
        f'<joint name="wrist" type="fixed">{newline}    <parent',
        f'<joint name="wrist" type="fixed">{newline}    <origin xyz="0.1 0.0 0.0" rpy="0.0 0.0 0.5"/>'
        f'{newline}    <parent',
    )
    assert result.text == expected != text
    shoulder, wrist = result.edits
    assert (shoulder.old_xyz, shoulder.new_xyz) == ("0  0 0.1", "0 0 0.25")  # as XML reads the tab
    assert shoulder.old_rpy == shoulder.new_rpy == "0  0 0"
    assert wrist.origin_added and wrist.old_xyz is None and wrist.new_rpy == "0.0 0.0 0.5"
    assert np.allclose(wrist.rpy_change, [0, 0, 0.5], atol=0, rtol=0)
    assert_reloads_as(result.text, origins)


def test_rpy_near_pi_does_not_jump_branch():
    text = TRAPS.replace(SHOULDER, "<origin xyz='0 0 0.1' rpy='3.14159 0.2 -3.14159'/>")
    T0 = joints_of(text)["shoulder"].T
    result = edit_joint_origins(text, {"shoulder": T0 @ transform(rotx(1e-5))})
    new_rpy = [float(v) for v in result.edits[0].new_rpy.split()]
    assert np.allclose(new_rpy, [3.14159, 0.2, -3.14159], atol=1e-4)
    assert_reloads_as(result.text, {"shoulder": T0 @ transform(rotx(1e-5))})


def test_missing_attributes_are_added_only_when_needed():
    text = TRAPS.replace(SHOULDER, '<origin  xyz="1 2 3" />')
    # rotation unchanged (zeros): no rpy attribute appears
    moved = edit_joint_origins(text, {"shoulder": transform(None, [1.0, 2.0, 3.5])}).text
    assert moved == text.replace('<origin  xyz="1 2 3" />', '<origin  xyz="1 2 3.5" />')
    turned = edit_joint_origins(text, {"shoulder": transform(rotz(-1.0), [1.0, 2.0, 3.0])}).text
    assert turned == text.replace('<origin  xyz="1 2 3" />', '<origin  xyz="1 2 3" rpy="0.0 0.0 -1.0" />')
    text = TRAPS.replace(SHOULDER, "<origin rpy='0 0 1'/>")
    placed = edit_joint_origins(text, {"shoulder": transform(rotz(1.0), [0.5, 0.0, 0.0])}).text
    assert placed == text.replace("<origin rpy='0 0 1'/>", "<origin rpy='0 0 1' xyz='0.5 0.0 0.0'/>")
    assert_reloads_as(placed, {"shoulder": transform(rotz(1.0), [0.5, 0.0, 0.0])})


def test_self_closing_joint_is_opened_only_if_needed():
    text = '<robot name="r">\n  <link name="a"/>\n  <joint name="j" type="fixed"/>\n</robot>\n'
    assert edit_joint_origins(text, {"j": np.eye(4)}).text == text
    edited = edit_joint_origins(text, {"j": transform(None, [0.1, 0, 0])}).text
    assert edited == text.replace('<joint name="j" type="fixed"/>',
                                  '<joint name="j" type="fixed"><origin xyz="0.1 0.0 0.0"/></joint>')
    check_urdf_text(edited)


def test_unknown_joint_lists_the_valid_ones():
    with pytest.raises(FrameError) as info:
        edit_joint_origins(TRAPS, {"sholder": np.eye(4)}, source="traps.urdf")
    assert info.value.valid == ("shoulder", "wrist")
    message = str(info.value)
    assert "'sholder'" in message and "Did you mean 'shoulder'" in message and "shoulder, wrist" in message
    # a name that only a transmission or gazebo block uses is not a joint
    text = TRAPS.replace('<joint name="shoulder"><origin', '<joint name="motor"><origin')
    with pytest.raises(FrameError, match="'motor'"):
        edit_joint_origins(text, {"motor": np.eye(4)})


@pytest.mark.parametrize("T", [np.diag([2.0, 1, 1, 1]), np.full((4, 4), np.nan), np.eye(3),
                               transform(np.diag([1.0, 1, -1]))])
def test_non_rigid_transform_is_refused(T):
    with pytest.raises(ExportError, match="'shoulder'"):
        edit_joint_origins(TRAPS, {"shoulder": T})


def test_bad_input_urdf_is_refused():
    with pytest.raises(UrdfError, match="xacro"):
        edit_joint_origins(TRAPS.replace("<link name='base'/>", "<xacro:include filename='x'/>"), {})
    with pytest.raises(UrdfError, match="'shoulder' is defined twice"):
        edit_joint_origins(TRAPS.replace("</robot>", "<joint name='shoulder' type='fixed'/></robot>"), {})
    with pytest.raises(UrdfError, match="not three numbers"):
        edit_joint_origins(TRAPS.replace("0  0\t0.1", "0 0.1"), {"shoulder": np.eye(4)})


def test_result_is_read_only():
    result = edit_joint_origins(TRAPS, {"shoulder": transform(rotx(0.1))})
    with pytest.raises(ValueError):
        result.edits[0].rpy_change[0] = 1.0
    assert result.for_joint("shoulder") is result.edits[0]
    with pytest.raises(FrameError):
        result.for_joint("wrist")


# ---------------------------------------------------------------- add_fixed_frame


def test_add_fixed_frame_appends_and_reloads():
    text = EC66.read_text()
    T = transform(Rotation.random(random_state=rng_for("frame")).as_matrix(), [0.01, -0.02, 0.15])
    new = add_fixed_frame(text, "link_6", "marker", "marker_joint", T)
    head = text[: text.rindex("</robot>")]
    assert new.startswith(head) and new.endswith("</robot>\n")
    added = new[len(head):]
    assert "<!-- added by kincal" in added and '<link name="marker"/>' in added
    check_urdf_text(new)
    assert_reloads_as(new, {"marker_joint": T})
    # the other joints are still editable in the extended text
    assert edit_joint_origins(new, {"joint_1": joints_of(text)["joint_1"].T}).text == new


def test_add_fixed_frame_refuses_bad_names():
    text = EC66.read_text()
    with pytest.raises(FrameError, match="'link_9'.*link_6") as info:
        add_fixed_frame(text, "link_9", "marker", "marker_joint", np.eye(4))
    assert "base_link" in info.value.valid
    with pytest.raises(FrameError, match="'link_1' already exists"):
        add_fixed_frame(text, "link_6", "link_1", "marker_joint", np.eye(4))
    with pytest.raises(FrameError, match="'joint_1' already exists"):
        add_fixed_frame(text, "link_6", "marker", "joint_1", np.eye(4))


# ---------------------------------------------------------------- write_text_atomic


def files_in(directory: Path) -> set[str]:
    return {p.name for p in directory.iterdir()}


def test_write_keeps_bytes_and_leaves_nothing_else(tmp_path):
    text = TRAPS.replace("\n", "\r\n")
    written = write_text_atomic(tmp_path / "out.urdf", text)
    assert written == (tmp_path / "out.urdf").resolve()
    assert written.read_bytes() == text.encode("utf-8")
    assert files_in(tmp_path) == {"out.urdf"}
    umask = os.umask(0)
    os.umask(umask)
    assert written.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600


def test_write_refuses_to_overwrite(tmp_path):
    target = tmp_path / "out.urdf"
    target.write_text("old")
    with pytest.raises(ExportError, match="already exists"):
        write_text_atomic(target, "new")
    assert target.read_text() == "old" and files_in(tmp_path) == {"out.urdf"}
    write_text_atomic(target, "new", overwrite=True)
    assert target.read_text() == "new" and files_in(tmp_path) == {"out.urdf"}


def test_write_refuses_protected_inputs_however_named(tmp_path, monkeypatch):
    source = tmp_path / "robot.urdf"
    source.write_text("input")
    (tmp_path / "link.urdf").symlink_to(source)
    os.link(source, tmp_path / "hard.urdf")
    monkeypatch.chdir(tmp_path)
    for spelling in ["robot.urdf", "./robot.urdf", tmp_path / "sub/../robot.urdf", "link.urdf", "hard.urdf"]:
        with pytest.raises(ExportError, match="input file"):
            write_text_atomic(spelling, "output", protect=[source])
    with pytest.raises(ExportError, match="input file"):  # protected given as a relative path
        write_text_atomic(source, "output", protect=["robot.urdf"])
    assert source.read_text() == "input"
    assert files_in(tmp_path) == {"robot.urdf", "link.urdf", "hard.urdf"}


def test_overwrite_replaces_no_input_but_the_urdf_in_place(tmp_path):
    """overwrite=True replaced a protected input by any output; now only the pairs of
    in_place (the corrected URDF over its robot description) may replace an input."""
    from kincal.export.safe_write import write_all

    robot, data = tmp_path / "robot.urdf", tmp_path / "data.csv"
    robot.write_text("robot")
    data.write_text("data")
    for target in (data, robot):
        with pytest.raises(ExportError, match="with or without --overwrite"):
            write_all([(target, "output")], overwrite=True, protect=[robot, data])
    with pytest.raises(ExportError, match="with or without --overwrite"):  # a URDF over data
        write_all([(data, "urdf")], overwrite=True, protect=[robot, data],
                  in_place=[(data, robot)])
    with pytest.raises(ExportError, match="or pass --overwrite"):  # in place, not asked
        write_all([(robot, "urdf")], protect=[robot, data], in_place=[(robot, robot)])
    assert robot.read_text() == "robot" and data.read_text() == "data"
    write_all([(tmp_path / "." / "robot.urdf", "urdf")], overwrite=True,
              protect=[robot, data], in_place=[(robot, robot)])
    assert robot.read_text() == "urdf" and data.read_text() == "data"


def test_write_refuses_missing_directory_without_creating_it(tmp_path):
    with pytest.raises(ExportError, match=f"directory {tmp_path / 'missing'} does not exist"):
        write_text_atomic(tmp_path / "missing" / "out.urdf", "x")
    assert files_in(tmp_path) == set()
    with pytest.raises(ExportError, match="is a directory"):
        write_text_atomic(tmp_path, "x", overwrite=True)


def test_write_in_read_only_directory(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("running with privileges that ignore directory permissions")
        with pytest.raises(ExportError, match="cannot write"):
            write_text_atomic(locked / "out.urdf", "x")
        assert files_in(locked) == set()
    finally:
        locked.chmod(0o700)


@pytest.mark.parametrize("failing", ["replace", "fsync"])
def test_failed_write_leaves_no_temporary_file(tmp_path, monkeypatch, failing):
    target = tmp_path / "out.urdf"
    target.write_text("old")

    def boom(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, failing, boom)
    with pytest.raises(ExportError, match="No space left"):
        write_text_atomic(target, "new", overwrite=True)
    monkeypatch.undo()
    assert files_in(tmp_path) == {"out.urdf"} and target.read_text() == "old"


@pytest.mark.parametrize("step,existing", [("link", None), ("replace", "old")])
def test_interrupted_write_leaves_no_temporary_file(tmp_path, monkeypatch, step, existing):
    # a new file is committed by os.link, a replaced one by os.replace
    if existing is not None:
        (tmp_path / "out.urdf").write_text(existing)

    def interrupt(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, step, interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_text_atomic(tmp_path / "out.urdf", "new", overwrite=existing is not None)
    monkeypatch.undo()
    assert files_in(tmp_path) == (set() if existing is None else {"out.urdf"})
    if existing is not None:
        assert (tmp_path / "out.urdf").read_text() == existing


def test_an_existing_output_names_the_api_s_way_to_replace_it(tmp_path):
    """An API user writing over a file was told "pass --overwrite", the command line's
    option; the line now gives the API's keyword too."""
    from kincal.export.safe_write import write_all

    out = tmp_path / "x.json"
    out.write_text("kept")
    with pytest.raises(ExportError) as exc:
        write_all([(out, "new")])
    assert str(exc.value) == (f"{out}: already exists; choose another output path or pass "
                              "--overwrite (Python: overwrite=True)")
    assert out.read_text() == "kept"
