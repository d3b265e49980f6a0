"""xacro files are expanded in Python (the PyPI xacro package) and then read as URDF."""

import warnings

import numpy as np
import pytest

from kincal.cli.main import main
from kincal.errors import KincalNote, UrdfError
from kincal.robot import Robot
from kincal.urdf_source import check_urdf_text, read_urdf_text

XACRO = """<?xml version="1.0"?>
<robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <!-- properties, math and a macro, as published descriptions use them -->
  <xacro:include filename="common.xacro"/>  <!-- relative to this file -->
  <xacro:property name="upper_len" value="${2 * half_upper}"/>
  <xacro:property name="twist" value="${pi / 2}"/>
  <xacro:macro name="segment" params="i parent length roll:=0">
    <link name="link_${i}"/>
    <joint name="joint_${i}" type="revolute">
      <parent link="${parent}"/>
      <child link="link_${i}"/>
      <origin xyz="${length * cos(roll)} 0.05 ${length}" rpy="${roll} 0 ${-twist / 3}"/>
      <axis xyz="0 0 1"/>
      <limit lower="${-radians(170)}" upper="${radians(170)}" effort="10" velocity="1"/>
    </joint>
  </xacro:macro>
  <link name="base_link"/>
  <xacro:segment i="1" parent="base_link" length="0.1"/>
  <xacro:segment i="2" parent="link_1" length="${upper_len}" roll="${twist}"/>
  <xacro:segment i="3" parent="link_2" length="${upper_len * 0.75}"/>
  <xacro:include filename="$(find tool_pkg)/urdf/tool.xacro"/>
  <xacro:tool parent="link_3"/>
</robot>
"""

TOOL = """<?xml version="1.0"?>
<robot xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:macro name="tool" params="parent">
    <link name="flange"/>
    <joint name="flange_joint" type="fixed">
      <parent link="${parent}"/><child link="flange"/>
      <origin xyz="0 0 ${0.1 + 0.02}" rpy="0 0 0"/>
    </joint>
  </xacro:macro>
</robot>
"""

def _segment(i, parent, length, roll=0.0):
    length, roll = float(length), float(roll)
    return f"""<link name="link_{i}"/>
  <joint name="joint_{i}" type="revolute"><parent link="{parent}"/><child link="link_{i}"/>
    <origin xyz="{length * float(np.cos(roll))!r} 0.05 {length!r}" rpy="{roll!r} 0 {-float(np.pi) / 6!r}"/>
    <axis xyz="0 0 1"/>
    <limit lower="{-float(np.radians(170))!r}" upper="{float(np.radians(170))!r}" effort="10" velocity="1"/>
  </joint>"""


# the same robot written out by hand
URDF = f"""<robot name="arm">
  <link name="base_link"/>
  {_segment(1, "base_link", 0.1)}
  {_segment(2, "link_1", 0.4, np.pi / 2)}
  {_segment(3, "link_2", 0.3)}
  <link name="flange"/>
  <joint name="flange_joint" type="fixed"><parent link="link_3"/><child link="flange"/>
    <origin xyz="0 0 0.12" rpy="0 0 0"/></joint>
</robot>
"""


@pytest.fixture
def workspace(tmp_path):
    """A ROS-like source tree: src/arm_pkg/urdf/arm.urdf.xacro and src/tool_pkg."""
    for pkg in ("arm_pkg", "tool_pkg"):
        (tmp_path / "src" / pkg / "urdf").mkdir(parents=True)
        (tmp_path / "src" / pkg / "package.xml").write_text(
            f"<?xml version='1.0'?>\n<package format='3'>\n  <name>{pkg}</name>\n</package>\n")
    arm = tmp_path / "src" / "arm_pkg" / "urdf" / "arm.urdf.xacro"
    arm.write_text(XACRO)
    (tmp_path / "src" / "tool_pkg" / "urdf" / "tool.xacro").write_text(TOOL)
    (arm.parent / "common.xacro").write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:property name="half_upper" value="0.2"/></robot>')
    plain = tmp_path / "arm.urdf"
    plain.write_text(URDF)
    return arm, plain


def test_xacro_loads_like_the_urdf_it_stands_for(workspace):
    arm, plain = workspace
    with pytest.warns(KincalNote, match="expanded with xacro"):
        robot = Robot.load(arm, tip="flange")
    reference = Robot.load(plain, tip="flange")
    assert robot.joint_names == reference.joint_names == ("joint_1", "joint_2", "joint_3")
    g, h = robot.geometry, reference.geometry
    np.testing.assert_allclose(g.joint_frames, h.joint_frames, atol=1e-12)
    np.testing.assert_allclose(g.T_base_tip, h.T_base_tip, atol=1e-12)
    np.testing.assert_allclose(g.upper, np.radians(170), atol=1e-12)
    check_urdf_text(robot.urdf_text)  # plain URDF, no xacro left


def test_xacro_namespace_alone_is_not_expanded(tmp_path):
    # generated URDFs often keep the xmlns:xacro declaration: read as they are, unchanged
    path = tmp_path / "generated.urdf"
    text = URDF.replace('<robot name="arm">',
                        '<robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">')
    path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert read_urdf_text(path) == text


def test_find_through_ros_package_path(workspace, tmp_path, monkeypatch):
    arm, _ = workspace
    elsewhere = tmp_path / "elsewhere" / "arm.urdf.xacro"  # not inside the source tree
    elsewhere.parent.mkdir()
    elsewhere.write_text(XACRO)
    (elsewhere.parent / "common.xacro").write_text((arm.parent / "common.xacro").read_text())
    monkeypatch.delenv("ROS_PACKAGE_PATH", raising=False)
    with pytest.raises(UrdfError, match=r"xacro expansion failed: \$\(find tool_pkg\): package "
                                        "'tool_pkg' not found.*ROS_PACKAGE_PATH"):
        read_urdf_text(elsewhere)
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "src"))
    with pytest.warns(KincalNote):
        assert "flange_joint" in read_urdf_text(elsewhere)


@pytest.mark.parametrize("change, reason", [
    (('length="0.1"', 'length="${shoulder}"'), "name 'shoulder' is not defined"),
    (("<xacro:tool parent", "<xacro:gripper parent"), "unknown macro name: xacro:gripper"),
    (("${upper_len * 0.75}", "${upper_len / 0}"), "division by zero"),
    (("<link name=\"base_link\"/>", "<link name=\"base_link\">"), "mismatched tag"),
])
def test_expansion_errors_are_one_line(workspace, change, reason):
    arm, _ = workspace
    arm.write_text(XACRO.replace(*change))
    with pytest.raises(UrdfError) as info:
        read_urdf_text(arm)
    message = str(info.value)
    assert reason in message and str(arm) in message and "\n" not in message


def test_calibrate_a_xacro_file_through_the_cli(workspace, tmp_path, capsys):
    arm, _ = workspace
    robot = Robot.load(workspace[1], tip="flange")
    rng = np.random.default_rng(1)
    q = rng.uniform(-2.5, 2.5, size=(25, 3))
    points = robot.tip_poses(q)[:, :3, 3] + [0.5, 0.1, 0.2]  # a measurement frame offset
    data = tmp_path / "data.csv"
    data.write_text("joint_1,joint_2,joint_3,x,y,z\n" + "".join(
        ",".join(repr(float(v)) for v in (*qk, *p)) + "\n" for qk, p in zip(q, points)))
    out = tmp_path / "cal.urdf"
    assert main(["analyze", str(arm), str(data), "--tip", "flange"]) == 0
    assert "expanded with xacro" in capsys.readouterr().err
    assert main(["calibrate", str(arm), str(data), "--tip", "flange", "--method", "frames",
                 "--out", str(out), "--quiet"]) == 0
    written = out.read_text()
    check_urdf_text(written)
    assert "flange_joint" in written and arm.read_text() == XACRO  # the xacro is untouched
    assert main(["analyze", str(arm).replace("arm.urdf", "nothere.urdf"), str(data)]) == 1


def test_a_refused_run_on_a_xacro_robot_is_its_one_error_line(workspace, tmp_path, capsys):
    """The note that a xacro file was expanded (how an input was read) came after the
    error line of a refused run: an error is one line, with the warnings that may explain
    it; the note is said when the run goes on."""
    arm, _ = workspace
    capsys.readouterr()
    assert main(["simulate", str(arm), "--tip", "flange", "--out", str(tmp_path / "s.csv")]) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("kincal: error: no default cube centre"), err
    assert not (tmp_path / "s.csv").exists()


def test_xacro_arguments_on_ur_description(tmp_path, capsys):
    """--xacro-arg NAME:=VALUE on every command that reads a robot: ur_description's
    ur.urdf.xacro (shared test data, BSD-3) needs ur_type and name; without them one line
    says so; with them it loads as the ur5e whose kinematics file it reads; a plain URDF
    refuses the option; a malformed one is named."""
    from conftest import SHARED

    xacro_file = SHARED / "data" / "ur_description" / "urdf" / "ur.urdf.xacro"
    if not xacro_file.exists():
        pytest.skip("../shared/data/ur_description is not present")
    out = tmp_path / "u.csv"
    assert main(["simulate", str(xacro_file), "--tip", "tool0", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.count("kincal: error:") == 1 and "--xacro-arg NAME:=VALUE" in err
    args = ["--xacro-arg", "ur_type:=ur5e", "--xacro-arg", "name:=ur5e"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = Robot.load(xacro_file, tip="tool0", xacro_args={"ur_type": "ur5e", "name": "ur5e"})
        ur10 = Robot.load(xacro_file, tip="tool0", xacro_args={"ur_type": "ur10", "name": "ur10"})
    assert robot.joint_names[0].endswith("shoulder_pan_joint")
    # the arguments reach the kinematics: a ur5e's upper arm is 425 mm, a ur10's 612 mm
    reach5 = np.linalg.norm(robot.tip_poses(np.zeros((1, 6)))[0, :3, 3])
    reach10 = np.linalg.norm(ur10.tip_poses(np.zeros((1, 6)))[0, :3, 3])
    assert 0.8 < reach5 < 0.9 and reach10 > reach5 + 0.3
    assert main(["simulate", str(xacro_file), *args, "--tip", "tool0", "--center-m", "0.4",
                 "0", "0.3", "--out", str(out)]) == 0
    cal = tmp_path / "u.urdf"
    assert main(["calibrate", str(xacro_file), str(out), *args, "--tip", "tool0", "--out",
                 str(cal)]) == 0
    capsys.readouterr()
    assert main(["simulate", "ec66", "--xacro-arg", "a:=b", "--out", str(tmp_path / "e.csv")]) == 1
    assert "is plain URDF, not xacro" in capsys.readouterr().err
    assert main(["simulate", str(xacro_file), "--xacro-arg", "ur_type", "--out",
                 str(tmp_path / "e.csv")]) == 1
    assert "expects NAME:=VALUE" in capsys.readouterr().err


ARG_XACRO = """<?xml version="1.0"?>
<robot name="arm" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <xacro:arg name="upper" default="0.4"/>
  <link name="base_link"/><link name="link_1"/><link name="link_2"/><link name="flange"/>
  <joint name="joint_1" type="revolute"><parent link="base_link"/><child link="link_1"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="joint_2" type="revolute"><parent link="link_1"/><child link="link_2"/>
    <origin xyz="0 0.05 $(arg upper)"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="flange_joint" type="revolute"><parent link="link_2"/><child link="flange"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
</robot>
"""


def test_compensate_takes_the_xacro_arguments_of_its_nominal(tmp_path, capsys):
    """--nominal-xacro-arg NAME:=VALUE reaches compensate's --nominal as --xacro-arg reaches
    ROBOT (the calibrated URDF kincal writes is plain URDF, which refuses --xacro-arg):
    a program planned on the nominal with upper:=0.5, compensated onto that same model,
    comes back unchanged; with the xacro's default (0.4) it does not."""
    xacro_file = tmp_path / "arm.urdf.xacro"
    xacro_file.write_text(ARG_XACRO)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        nominal = Robot.load(xacro_file, tip="flange", xacro_args={"upper": "0.5"})
    cal = tmp_path / "cal.urdf"
    cal.write_text(nominal.urdf_text)  # the "calibrated" robot: the nominal itself, plain
    q = np.random.default_rng(3).uniform(-1.0, 1.0, size=(6, 3))
    prog = tmp_path / "program.csv"
    prog.write_text("joint_1,joint_2,flange_joint\n" + "".join(
        ",".join(repr(float(v)) for v in row) + "\n" for row in q))

    def run(*extra, out="j.csv"):
        return main(["compensate", str(cal), "--program", str(prog), "--nominal",
                     str(xacro_file), "--tip", "flange", "--out", str(tmp_path / out),
                     "--quiet", *extra])

    def joints(out):
        lines = [s for s in (tmp_path / out).read_text().splitlines() if not s.startswith("#")]
        table = np.array([[float(v) for v in s.split(",")] for s in lines[1:]])
        return table[:, 1:4]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert run("--nominal-xacro-arg", "upper:=0.5") == 0
        np.testing.assert_allclose(joints("j.csv"), q, atol=1e-6)
        assert run("--flag-unreachable", out="default.csv") == 0
        assert np.abs(joints("default.csv") - q).max() > 1e-3  # upper 0.4: another model
    capsys.readouterr()
    assert run("--nominal-xacro-arg", "upper", out="bad.csv") == 1
    assert "--nominal-xacro-arg expects NAME:=VALUE" in capsys.readouterr().err
    assert main(["compensate", str(cal), "--program", str(prog), "--nominal-xacro-arg",
                 "upper:=0.5", "--tip", "flange", "--out", str(tmp_path / "x.csv")]) == 1
    assert "needs --nominal" in capsys.readouterr().err
    assert main(["compensate", str(cal), "--program", str(prog), "--nominal", str(cal),
                 "--nominal-xacro-arg", "upper:=0.5", "--tip", "flange", "--out",
                 str(tmp_path / "y.csv")]) == 1  # a plain nominal refuses them
    assert f"{cal}: is plain URDF, not xacro" in capsys.readouterr().err
    assert not any((tmp_path / n).exists() for n in ("bad.csv", "x.csv", "y.csv"))


def test_api_files_name_the_xacro_arguments_the_robot_was_loaded_with(tmp_path):
    """Robot.load(xacro, xacro_args=...) keeps the arguments: files written through the API
    (write_calibration, no xacro_args given) name them in their provenance as the command
    line's do; the robot's corrected copy keeps them; a plain URDF has none."""
    import json

    from kincal import Measurements, Outputs, calibrate, write_calibration

    xacro_file = tmp_path / "arm.urdf.xacro"
    xacro_file.write_text(ARG_XACRO)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = Robot.load(xacro_file, tip="flange", xacro_args={"upper": "0.5"})
        rng = np.random.default_rng(0)
        q = rng.uniform(-1.5, 1.5, size=(40, 3))
        T = robot.tip_poses(q)
        P = T[:, :3, 3] + T[:, :3, :3] @ [0.05, 0.02, 0.03] + rng.normal(0, 2e-5, (40, 3))
        data = tmp_path / "d.csv"
        data.write_text("joint_1,joint_2,flange_joint,x,y,z\n" + "".join(
            ",".join(repr(float(v)) for v in row) + "\n" for row in np.hstack([q, P])))
        result = calibrate(robot, Measurements.from_csv(data, robot.joint_names))
        write_calibration(result, Outputs(urdf=tmp_path / "c.urdf",
                                          report=tmp_path / "r.json"))
    assert robot.xacro_args == (("upper", "0.5"),)
    assert result.corrected.xacro_args == (("upper", "0.5"),)
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["provenance"]["robot"]["xacro_args"] == {"upper": "0.5"}
    assert "xacro args: upper:=0.5" in (tmp_path / "c.urdf").read_text()
    assert Robot.load("ec66").xacro_args == ()


def test_an_argument_the_xacro_neither_declares_nor_uses_is_refused(tmp_path, capsys):
    """xacro ignores an argument no file declares or uses: a misspelt kinematics_params
    expanded ur_description's default robot (and gave its hash to --yaml-format ur) without
    a word. kincal refuses it in one line naming the file's arguments, in the CLI (here
    simulate; every command reads the robot alike) and in the API, and writes nothing."""
    xacro_file = tmp_path / "arm.urdf.xacro"
    xacro_file.write_text(ARG_XACRO.replace(
        '<link name="base_link"/>', '<xacro:arg name="unused" default="1"/><link name="base_link"/>'))
    with pytest.raises(UrdfError, match=r"xacro argument uper is neither declared nor used .*"
                                        r"its arguments: unused, upper\. Did you mean 'upper'"):
        Robot.load(xacro_file, tip="flange", xacro_args={"uper": "0.5"})
    out = tmp_path / "d.csv"
    assert main(["simulate", str(xacro_file), "--xacro-arg", "upper:=0.5", "--xacro-arg",
                 "uper:=0.5", "--tip", "flange", "--center-m", "0.3", "0", "0.3",
                 "--out", str(out)]) == 1
    err = [s for s in capsys.readouterr().err.splitlines() if s.startswith("kincal: error:")]
    assert len(err) == 1 and "xacro argument uper is neither declared nor used" in err[0]
    assert not out.exists()
    with warnings.catch_warnings():  # declared but unused and used: both are arguments
        warnings.simplefilter("ignore")
        Robot.load(xacro_file, tip="flange", xacro_args={"upper": "0.5", "unused": "2"})
