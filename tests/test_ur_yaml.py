"""--yaml-format ur: ur_description's kinematics file, read back through ur.urdf.xacro."""

from pathlib import Path

import numpy as np
import pytest

from kincal.cli import main
from kincal.robot import Robot

UR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "ur_description"
XACRO = UR / "urdf" / "ur.urdf.xacro"
pytestmark = pytest.mark.skipif(not XACRO.is_file(), reason="ur_description is absent")


def _args(params):
    return {"ur_type": "ur10e", "name": "ur", "kinematics_params": str(params)}


def _cli_args(params):
    return [a for k, v in _args(params).items() for a in ("--xacro-arg", f"{k}:={v}")]


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ur")
    factory = tmp / "FACTORY.yaml"
    text = (UR / "config" / "ur10e" / "default_kinematics.yaml").read_text()
    factory.write_text(text.replace("calib_5119701370761913513", "calib_kincal_test_42"))
    data = tmp / "data.csv"
    assert main(["simulate", str(XACRO), *_cli_args(factory), "--tip", "tool0",
                 "--tool-m", "0.01", "0.02", "0.1", "--center-m", "0.7", "0.0", "0.4", "--length-error-mm", "1",
                 "--angle-error-deg", "0.1", "--noise-mm", "0", "--poses", "60",
                 "--out", str(data)]) == 0
    assert main(["calibrate", str(XACRO), str(data), *_cli_args(factory), "--tip", "tool0",
                 "--out", str(tmp / "C.urdf"), "--yaml-out", str(tmp / "K.yaml"),
                 "--yaml-format", "ur", "--quiet"]) == 0
    return tmp, factory, data


def test_ur_yaml_loads_through_the_xacro_and_matches_the_corrected_urdf(calibrated):
    tmp, factory, _ = calibrated
    text = (tmp / "K.yaml").read_text()
    assert "  hash: calib_kincal_test_42\n" in text
    body = [line for line in text.splitlines() if not line.startswith("#")]
    assert body[0] == "kinematics:" and body[1] == "  shoulder:" and body[-1].startswith("  hash:")
    wrist_3 = body[body.index("  wrist_3:") + 1:body.index("  wrist_3:") + 7]
    assert abs(float(wrist_3[4].split(":")[1]) - np.pi) < 0.01  # the factory's r, pi, pi branch
    via_yaml = Robot.load(str(XACRO), tip="tool0", xacro_args=_args(tmp / "K.yaml"))
    corrected = Robot.load(str(tmp / "C.urdf"), tip="tool0")
    nominal = Robot.load(str(XACRO), tip="tool0", xacro_args=_args(factory))
    q = np.random.default_rng(0).uniform(-np.pi, np.pi, (50, 6))
    p = via_yaml.tip_poses(q)[:, :3, 3]  # tool0 in base_link [m]
    worst = np.linalg.norm(p - corrected.tip_poses(q)[:, :3, 3], axis=1).max()
    moved = np.linalg.norm(p - nominal.tip_poses(q)[:, :3, 3], axis=1).max()
    assert worst < 1e-9
    assert moved > 1e-4  # the file carries the correction, not the factory values


def test_ur_hash_overrides(calibrated, tmp_path):
    tmp, factory, data = calibrated
    assert main(["calibrate", str(XACRO), str(data), *_cli_args(factory), "--tip", "tool0",
                 "--out", str(tmp_path / "C.urdf"), "--yaml-out", str(tmp_path / "K.yaml"),
                 "--yaml-format", "ur", "--ur-hash", "calib_given", "--quiet"]) == 0
    text = (tmp_path / "K.yaml").read_text()
    assert "  hash: calib_given\n" in text
    assert "factory" not in text.splitlines()[0]  # it said "the hash is the factory file's"


def test_a_given_hash_reads_back_as_given(calibrated, tmp_path, capsys):
    """--ur-hash was written as typed: "a: b" made the file unreadable YAML, "c_1 #x" read
    back as c_1, "12345" as a number, "on" as True; now such a hash is quoted (a plain
    calib_... stays plain, as the factory file has it) and an empty one is refused."""
    import yaml

    tmp, factory, data = calibrated
    base = ["calibrate", str(XACRO), str(data), *_cli_args(factory), "--tip", "tool0",
            "--yaml-format", "ur", "--quiet", "--model", "mdh", "--method", "ls"]
    for k, given in enumerate(("a: b", "c_1 #x", "12345", "on", 'q"uote')):
        out = tmp_path / f"K{k}.yaml"
        assert main(base + ["--out", str(tmp_path / f"C{k}.urdf"), "--yaml-out", str(out),
                            "--ur-hash", given]) == 0
        assert yaml.safe_load(out.read_text())["kinematics"]["hash"] == given
    _refused(base + ["--out", str(tmp_path / "E.urdf"), "--yaml-out", str(tmp_path / "E.yaml"),
                     "--ur-hash", " "], capsys, "--ur-hash is empty")
    assert not (tmp_path / "E.urdf").exists()


def _refused(argv, capsys, *words):
    assert main(argv) != 0
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("kincal: error:")]
    assert len(err) == 1 and all(w in err[0] for w in words), err


def test_format_and_hash_need_yaml_out(calibrated, tmp_path, capsys):
    _, factory, data = calibrated
    base = ["calibrate", str(XACRO), str(data), *_cli_args(factory), "--tip", "tool0",
            "--out", str(tmp_path / "C.urdf")]
    _refused(base + ["--yaml-format", "ur"], capsys, "--yaml-out")
    _refused(base + ["--ur-hash", "x"], capsys, "--yaml-out")
    assert not (tmp_path / "C.urdf").exists()


def test_a_hash_goes_with_the_ur_format_only(calibrated, tmp_path, capsys):
    """--ur-hash with the kincal YAML (joint-name keys, no hash) was accepted and dropped:
    the user got a file ur_description cannot read; refused, in the CLI and the API."""
    from kincal import Measurements, Outputs, calibrate, write_calibration
    from kincal.errors import ExportError

    tmp, factory, data = calibrated
    base = ["calibrate", str(XACRO), str(data), *_cli_args(factory), "--tip", "tool0",
            "--out", str(tmp_path / "C.urdf"), "--yaml-out", str(tmp_path / "K.yaml"),
            "--ur-hash", "calib_1"]
    _refused(base, capsys, "--ur-hash", "--yaml-format ur")
    _refused(base + ["--yaml-format", "kincal"], capsys, "--ur-hash", "--yaml-format ur")
    robot = Robot.load(str(XACRO), tip="tool0", xacro_args=_args(factory))
    result = calibrate(robot, Measurements.from_csv(data, robot.joint_names), model="mdh",
                       method="ls")
    with pytest.raises(ExportError, match="ur_hash .*yaml_format='ur'"):
        write_calibration(result, Outputs(urdf=tmp_path / "C.urdf", yaml=tmp_path / "K.yaml",
                                          ur_hash="calib_1"))
    assert not any(tmp_path.iterdir())


def test_a_relative_kinematics_file_gives_the_hash_of_the_file_xacro_read(calibrated, tmp_path,
                                                                         monkeypatch):
    """xacro reads a relative kinematics_params beside the xacro file that loads it
    (ur_description's urdf/); the hash was read relative to the working folder instead:
    another robot's hash from a file of the same name there, or "no hash found"."""
    import re

    _, _, data = calibrated
    relative = "../config/ur10e/default_kinematics.yaml"  # from urdf/: the factory file
    read = (XACRO.parent / relative).read_text()
    expected = re.search(r"hash:\s*(\S+)", read).group(1)
    cell = tmp_path / "cell"  # the working folder holds another file at the same name
    (cell / "config" / "ur10e").mkdir(parents=True)
    (cell / "urdf").mkdir()
    (cell / "config" / "ur10e" / "default_kinematics.yaml").write_text(
        read.replace(expected, "calib_another_robot"))
    for k, folder in enumerate((cell / "urdf", tmp_path)):  # there, and where none is
        monkeypatch.chdir(folder)
        out = tmp_path / f"K{k}.yaml"
        assert main(["calibrate", str(XACRO), str(data), "--xacro-arg", "ur_type:=ur10e",
                     "--xacro-arg", "name:=ur", "--xacro-arg", f"kinematics_params:={relative}",
                     "--tip", "tool0", "--model", "mdh", "--method", "ls", "--quiet",
                     "--out", str(tmp_path / f"C{k}.urdf"), "--yaml-out", str(out),
                     "--yaml-format", "ur"]) == 0
        assert out.read_text().endswith(f"  hash: {expected}\n")


def test_ur_format_needs_the_six_ur_joints(calibrated, tmp_path, capsys):
    _, factory, data = calibrated
    _refused(["calibrate", str(XACRO), str(data), *_cli_args(factory), "--tip", "wrist_2_link",
              "--out", str(tmp_path / "C.urdf"), "--yaml-out", str(tmp_path / "K.yaml"),
              "--yaml-format", "ur"], capsys, "six UR joints")


def test_no_hash_found_says_pass_ur_hash(calibrated, tmp_path, capsys):
    # a plain URDF of a UR (here kincal's corrected one) was expanded from no kinematics file
    tmp, _, data = calibrated
    _refused(["calibrate", str(tmp / "C.urdf"), str(data), "--tip", "tool0",
              "--out", str(tmp_path / "C.urdf"), "--yaml-out", str(tmp_path / "K.yaml"),
              "--yaml-format", "ur"], capsys, "--ur-hash")
    assert not (tmp_path / "C.urdf").exists()


def test_provenance_of_a_xacro_description(calibrated):
    import hashlib

    tmp, factory, data = calibrated
    urdf = (tmp / "C.urdf").read_text()
    head = urdf[:urdf.index("-->")]
    assert f"robot: {XACRO} sha256 {hashlib.sha256(XACRO.read_bytes()).hexdigest()}" in head
    assert f"xacro args: kinematics_params:={factory} name:=ur ur_type:=ur10e" in head
    assert "autogenerated" not in urdf.lower()  # xacro's banner went, with its advice
    yaml = (tmp / "K.yaml").read_text()
    assert f"# data: {data} sha256 {hashlib.sha256(data.read_bytes()).hexdigest()}" in yaml


def test_api_refuses_an_empty_hash(calibrated, tmp_path):
    """write_calibration(result, Outputs(yaml=..., yaml_format="ur", ur_hash=" ")) and
    ur_kinematics_yaml(...) refuse a blank hash as --ur-hash " " is refused (before, the
    API wrote 'hash: "   "', a file no controller's hash matches, without a word)."""
    from kincal import Outputs, write_calibration
    from kincal.errors import ExportError
    from kincal.export.cell_exports import ur_kinematics_yaml

    tmp, factory, _ = calibrated
    robot = Robot.load(str(XACRO), tip="tool0", xacro_args=_args(factory))
    for blank in ("", "   ", None):
        with pytest.raises(ExportError, match="ur_hash"):
            ur_kinematics_yaml(robot, robot, blank)
    from kincal import Measurements, calibrate

    data = Measurements.from_csv(tmp / "data.csv", robot.joint_names)
    result = calibrate(robot, data, model="mdh", method="ls")
    with pytest.raises(ExportError, match="ur_hash: it is empty"):
        write_calibration(result, Outputs(urdf=tmp_path / "C.urdf", yaml=tmp_path / "K.yaml",
                                          yaml_format="ur", ur_hash="   "))
    assert not any(tmp_path.iterdir())


def test_a_flush_face_tilt_stays_in_frames_json_beside_a_ur_kinematics_file(calibrated, tmp_path,
                                                                            capsys):
    """ur_description's kinematics file has no place for a flush face's tilt: with
    --yaml-format ur it is not folded into the URDF (which the YAML must describe) and stays
    in FRAMES.json, with a note; without it, the URDF carries it as before."""
    import json

    _, factory, _ = calibrated
    flush = tmp_path / "flush.csv"
    assert main(["simulate", str(XACRO), *_cli_args(factory), "--tip", "tool0", "--kind",
                 "flush", "--center-m", "0.7", "0.0", "0.4", "--poses", "40", "--seed", "2",
                 "--out", str(flush)]) == 0
    common = ["calibrate", str(XACRO), str(flush), *_cli_args(factory), "--tip", "tool0",
              "--on-plane", "--flush", "--tool-offset", "0", "0", "0.1"]
    capsys.readouterr()
    assert main(common + ["--out", str(tmp_path / "U.urdf"), "--frames-out",
                          str(tmp_path / "U.json"), "--yaml-out", str(tmp_path / "U.yaml"),
                          "--yaml-format", "ur"]) == 0
    said = capsys.readouterr().out
    assert "stays in FRAMES.json only: ur_description's kinematics file" in said
    frames = json.loads((tmp_path / "U.json").read_text())
    assert frames["sets"][0]["frames"]["tool.ry"] != 0.0 and "tilts_in_urdf" not in frames
    assert main(common + ["--out", str(tmp_path / "K.urdf"), "--frames-out",
                          str(tmp_path / "K.json")]) == 0
    frames = json.loads((tmp_path / "K.json").read_text())
    assert frames["sets"][0]["frames"]["tool.ry"] == 0.0 and frames["tilts_in_urdf"]
