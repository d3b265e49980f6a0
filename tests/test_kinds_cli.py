"""The command line with measurement kinds: simulate --kind, several files, errors."""

import json

import numpy as np
import pytest

from kincal.cli.main import main


def run(capsys, *argv):
    code = main(list(map(str, argv)))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_simulate_every_kind_and_calibrate_them_together(tmp_path, capsys):
    files = []
    for k, kind in enumerate(("point", "pose", "distance", "plane")):
        path = tmp_path / f"{kind}.csv"
        code, out, err = run(capsys, "simulate", "ec66", "--kind", kind, "--poses", 24,
                             "--out", path, "--seed", k)
        assert code == 0, err
        files.append(path)
    header = {p.stem: next(line for line in p.read_text().splitlines()
                           if not line.startswith("#")).split(",") for p in files}
    assert {"qx", "qy", "qz", "qw"} <= set(header["pose"])
    assert header["distance"][-1] == "distance" and header["plane"][-1] == "plane"
    code, out, err = run(capsys, "calibrate", "ec66", *files, "--on-plane", "--lambda", 0.1,
                         "--out", tmp_path / "cal.urdf", "--frames-out", tmp_path / "f.json")
    assert code == 0, err
    assert "4 measurement set(s)" in out and "set 4: plane" in out
    sets = json.loads((tmp_path / "f.json").read_text())["sets"]
    assert [s["kind"] for s in sets] == ["point", "pose", "distance", "plane"]
    assert "tool.rz" in sets[1]["frames"] and "pivot.x" in sets[2]["frames"]
    assert "plane1.d" in sets[3]["frames"] and "set4.plane1.d" in out
    code, out, err = run(capsys, "evaluate", tmp_path / "cal.urdf", files[2], "--tip", "flange",
                         "--frames", tmp_path / "f.json")
    assert code == 0, err
    mean = float(out.split("mean ")[1].split()[0])
    assert mean < 0.1  # [mm] the calibrated model on its own distances
    code, out, err = run(capsys, "analyze", "ec66", files[3], "--on-plane")
    assert code == 0 and "plane contact sees only motion along the plane's normal" in out


def test_simulate_plane_says_how_many_contacts_it_wrote(tmp_path, capsys):
    """Plane contacts come as a whole number on each of the 3 planes (at least 3): the
    line and --json say what the file holds, not the --poses asked (40 asked gave 39
    rows, 4 asked 9, both reported as asked)."""
    for asked, rows in ((40, 39), (4, 9), (30, 30)):
        path = tmp_path / f"c{asked}.csv"
        code, out, err = run(capsys, "simulate", "ec66", "--kind", "plane", "--poses", asked,
                             "--out", path, "--json")
        assert code == 0, err
        written = [line for line in path.read_text().splitlines()
                   if not line.startswith("#")][1:]
        assert len(written) == rows and json.loads(out)["poses"] == rows
        code, out, err = run(capsys, "simulate", "ec66", "--kind", "plane", "--poses", asked,
                             "--out", path, "--overwrite")
        assert f"at {rows} poses" in out
        assert (f"{rows // 3} on each of 3 planes, {asked} asked" in out) == (rows != asked)


def test_ambiguous_and_bad_files_one_line_error(tmp_path, capsys):
    path = tmp_path / "both.csv"
    rows = np.random.default_rng(0).normal(size=(5, 10))
    path.write_text("joint_1,joint_2,joint_3,joint_4,joint_5,joint_6,x,y,z,distance\n"
                    + "\n".join(",".join(map(repr, r)) for r in rows) + "\n")
    code, out, err = run(capsys, "calibrate", "ec66", path, "--out", tmp_path / "c.urdf")
    assert code == 1 and err.count("\n") == 1 and "kincal: error:" in err
    assert "is it distances to a pivot or measured points?" in err
    assert not (tmp_path / "c.urdf").exists()


def test_flush_contacts_from_simulation_to_calibration_and_plan(tmp_path, capsys):
    """--kind flush end to end: simulated touches within the joint limits, calibrated with
    --on-plane --flush (heights to the noise), evaluated from the frames, planned among."""
    data, out, frames = tmp_path / "f.csv", tmp_path / "c.urdf", tmp_path / "f.json"
    assert main(["simulate", "ec66", "--kind", "flush", "--poses", "30", "--out", str(data),
                 "--seed", "3"]) == 0
    assert main(["calibrate", "ec66", str(data), "--on-plane", "--flush", "--tool-offset", "0",
                 "0", "0.1", "--out", str(out), "--frames-out", str(frames)]) == 0
    text = capsys.readouterr().out
    assert "flush" in text and "tilt against the plane after" in text
    after = float(text.split("after:  mean ")[1].split()[0])
    assert after < 0.1  # [mm] heights to the 0.05 mm noise
    saved = json.loads(frames.read_text())
    assert saved["sets"][0]["kind"] == "flush"
    # the contact point, which flush touches cannot see, stays exactly at --tool-offset
    # (the start fit included: issue 18 item 4)
    assert saved["tool"] == {"x": 0.0, "y": 0.0, "z": 0.1}
    assert any(k.startswith("plane") and k.endswith("_in_base") for k in saved["sets"][0])
    assert main(["evaluate", str(out), str(data), "--frames", str(frames), "--on-plane",
                 "--flush"]) == 0
    assert "(flush errors)" in capsys.readouterr().out
    assert main(["plan", "ec66", str(data), "--kind", "flush", "--poses", "10",
                 "--tool-offset", "0.02", "0", "0.1", "--out", str(tmp_path / "p.csv"),
                 "--noise-mm", "0.1"]) == 0
    # the predicted errors name the noise of each row: heights and tilts (the tilt rows weigh
    # as a set stating no sigma weighs them: 0.05 deg against 0.05 mm); was "mm per axis"
    assert ("largest predicted std errors at a noise of 0.1 mm per height and 0.1 deg per "
            "tilt:") in capsys.readouterr().out
    assert main(["plan", "ec66", str(data), "--kind", "flush", "--poses", "10", "--json",
                 "--tool-offset", "0.02", "0", "0.1", "--out", str(tmp_path / "p2.csv")]) == 0
    assert json.loads(capsys.readouterr().out)["noise"] == "0.05 mm per height and 0.05 deg per tilt"
    assert main(["simulate", "ec66", "--kind", "point", "--orientation-noise-deg", "0.1",
                 "--out", str(tmp_path / "x.csv")]) == 1


def test_evaluate_judges_each_file_with_the_frames_calibrated_on_it(tmp_path, capsys):
    """Two flush files of one chain (two sessions, each its own table): kincal evaluate of
    either file with FRAMES.json gives the error the calibration reported for it. Before,
    the second file was judged with the first one's table (1.5 mm instead of 0.08)."""
    files = []
    for k in (1, 2):
        files.append(str(tmp_path / f"session{k}.csv"))
        assert main(["simulate", "ec66", "--kind", "flush", "--poses", "30", "--seed", str(k),
                     "--truth-seed", "5", "--tool-m", "0.01", "0.02", "0.1", "--out",
                     files[-1], "-q"]) == 0
    frames, report = str(tmp_path / "f.json"), str(tmp_path / "r.json")
    assert main(["calibrate", "ec66", *files, "--on-plane", "--flush", "--tool-offset", "0.01",
                 "0.02", "0.1", "--model", "offsets", "--out", str(tmp_path / "c.urdf"),
                 "--frames-out", frames, "--report", report, "-q"]) == 0
    reported = [s["errors"]["after"]["mean_mm"]
                for s in json.loads(open(report).read())["sets"]]
    capsys.readouterr()
    for path, after in zip(files, reported):
        assert main(["evaluate", str(tmp_path / "c.urdf"), path, "--on-plane", "--flush",
                     "--frames", frames, "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["errors"]["mean_mm"] == pytest.approx(
            after, rel=1e-9)


def test_html_report_for_kinds_without_positions(tmp_path, capsys):
    """--html on distances, plane and flush contacts: the report is written (no accuracy
    map: no point or pose set to predict, said on the page); --accuracy-map on such data
    is refused before any fit, nothing written. Before, --html failed after the fit with
    the accuracy map's error and wrote nothing."""
    for kind, extra in (("distance", ()), ("plane", ("--on-plane",)),
                        ("flush", ("--on-plane", "--flush", "--tool-offset", 0, 0, 0.1))):
        data = tmp_path / f"{kind}.csv"
        code, _, err = run(capsys, "simulate", "ec66", "--kind", kind, "--poses", 40,
                           "--out", data, "--seed", 3)
        assert code == 0, err
        page = tmp_path / f"{kind}.html"
        code, out, err = run(capsys, "calibrate", "ec66", data, *extra, "--out",
                             tmp_path / f"{kind}.urdf", "--html", page)
        assert code == 0, err
        assert "No accuracy map in this run." in page.read_text()
        before = sorted(p.name for p in tmp_path.iterdir())
        code, out, err = run(capsys, "calibrate", "ec66", data, *extra, "--out",
                             tmp_path / f"{kind}2.urdf", "--accuracy-map", 0.4, 0, 0.3, 0.2)
        assert code == 1 and err.count("kincal: error:") == 1, err
        assert f"these data have none ({kind})" in err
        assert sorted(p.name for p in tmp_path.iterdir()) == before
        code, out, err = run(capsys, "analyze", "ec66", data, *extra, "--accuracy-map", 0.4, 0,
                             0.3, 0.2)
        assert code == 1 and f"these data have none ({kind})" in err and not out, (out, err)


def test_accuracy_map_of_pose_data_gives_the_orientation_in_degrees(tmp_path, capsys):
    """calibrate and analyze --accuracy-poses on 6-DoF poses: the map's summary and its JSON
    give the tool frame's predicted orientation error [deg] per pose as well; points keep
    the position figures alone."""
    for kind in ("pose", "point"):
        code, out, err = run(capsys, "simulate", "ec66", "--kind", kind, "--poses", 30,
                             "--out", tmp_path / f"{kind}.csv", "--seed", 4, "-q")
        assert code == 0, err
    for kind in ("pose", "point"):
        data = tmp_path / f"{kind}.csv"
        for command in (("calibrate", "--lambda", 0.01, "--out", tmp_path / f"{kind}.urdf"),
                        ("analyze",)):
            report = tmp_path / f"{kind}-{command[0]}.json"
            code, out, err = run(capsys, command[0], "ec66", data, *command[1:],
                                 "--accuracy-poses", data, "--report", report)
            assert code == 0, err
            amap = json.loads(report.read_text())["accuracy_map"]
            if kind == "point":
                assert "orientation" not in out and "orientation_std_deg" not in amap
                continue
            per_pose = amap["orientation_std_per_pose_deg"]
            assert len(per_pose) == amap["reached"] == 30
            # 0.01 deg orientation noise per axis over 30 poses: thousandths of a degree
            assert 1e-4 < amap["orientation_std_deg"]["median"] < 0.01
            assert amap["orientation_std_deg"]["max"] == max(per_pose)
            assert f"orientation std (tool frame): median {np.median(per_pose):.4f}" in out
            assert f"max {max(per_pose):.4f} deg" in out


def test_distances_in_a_small_volume_start_from_the_pivot_and_tool_they_fix(tmp_path, capsys):
    """Distances from a 20 mm cube with tilts to 60 deg, no --tool-offset: the start put
    the tool at the tip origin and its sphere's pivot far off, and the fit ended in a false
    minimum written without a word (3.3 mm RMS left against 0.05 mm noise); the closed-form
    pivot-and-tool start reaches the noise."""
    from kincal.measurements.distance import pivot_and_tool

    data, out, rep = tmp_path / "d.csv", tmp_path / "c.urdf", tmp_path / "r.json"
    assert main(["simulate", "ec66", "--in-cube", "0.4", "0", "0.25", "0.02", "--max-tilt",
                 "60", "--kind", "distance", "--out", str(data), "--seed", "1"]) == 0
    assert main(["calibrate", "ec66", str(data), "--out", str(out), "--report",
                 str(rep)]) == 0
    after = json.loads(rep.read_text())["errors"]["after"]["rms_mm"]
    assert after < 0.08  # [mm], noise 0.05 mm
    # the closed form itself: exact on exact distances
    rng = np.random.default_rng(0)
    R = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0] for _ in range(30)])
    R *= np.linalg.det(R)[:, None, None]
    p, c, t = rng.normal(0, 0.3, (30, 3)), np.array([0.5, -0.2, 0.1]), np.array([0.01, 0.02, 0.1])
    d = np.linalg.norm(p + R @ t - c, axis=1)
    (f,) = pivot_and_tool(p, R, d)
    assert np.allclose(f, np.r_[c, t], atol=1e-9)
    assert pivot_and_tool(p[:15], R[:15], d[:15]) == []


@pytest.mark.parametrize("kind,flush", [("pose", True), ("point", False), ("distance", False)])
def test_on_plane_with_no_contact_file_is_refused(tmp_path, capsys, kind, flush):
    """--on-plane (--flush) reads files of joint columns alone as contacts; a file with
    measurement columns (a robot log carrying its floating base's x y z qx qy qz qw) is
    read as its kind. With no contact file at all the option was used nowhere and the file
    calibrated as what it is without a word: refused, naming each file's kind."""
    data = tmp_path / f"{kind}.csv"
    assert run(capsys, "simulate", "ec66", "--kind", kind, "--poses", 24, "--out", data)[0] == 0
    out_urdf = tmp_path / "cal.urdf"
    code, out, err = run(capsys, "calibrate", "ec66", data, "--on-plane",
                         *(["--flush"] if flush else []), "--out", out_urdf)
    lines = [line for line in err.splitlines() if line.startswith("kincal: error:")]
    assert code != 0 and len(lines) == 1, err
    assert "--on-plane" in lines[0] and f"{kind}.csv: {kind}" in lines[0]
    assert not out_urdf.exists()
    # with one contact file beside it, the option is used: accepted
    plane = tmp_path / "plane.csv"
    assert run(capsys, "simulate", "ec66", "--kind", "plane", "--poses", 24, "--out", plane)[0] == 0
    code, out, err = run(capsys, "calibrate", "ec66", data, plane, "--on-plane", "--lambda", 0.1,
                         "--out", out_urdf)
    assert code == 0, err


def test_a_plane_named_by_a_word_is_refused_saying_planes_are_numbered(tmp_path, capsys):
    """A contact file naming its planes by words ('wall') was refused as "expected a finite
    number", right but not saying what the column holds: the line now says planes are
    numbered."""
    data = tmp_path / "plane.csv"
    assert run(capsys, "simulate", "ec66", "--kind", "plane", "--poses", 24, "--out", data)[0] == 0
    lines = data.read_text().splitlines()
    body = [k for k, line in enumerate(lines) if not line.startswith("#")]
    k = body[3]  # the third touch
    lines[k] = lines[k].rsplit(",", 1)[0] + ",wall"
    data.write_text("\n".join(lines) + "\n")
    code, out, err = run(capsys, "calibrate", "ec66", data, "--on-plane", "--out",
                         tmp_path / "c.urdf")
    errors = [line for line in err.splitlines() if line.startswith("kincal: error:")]
    assert code == 1 and len(errors) == 1, err
    assert f"line {k + 1}, column 'plane': 'wall'; expected a finite number" in errors[0]
    assert "the plane's number" in errors[0] and not (tmp_path / "c.urdf").exists()


def test_on_plane_training_with_a_held_out_point_file(tmp_path, capsys):
    """--on-plane is the training's: a held-out file of points (--validate) beside points
    and contacts in training is read as points, not refused as a run with no contact file
    (the check of --on-plane judged the held-out file alone)."""
    files = {}
    for name, kind, seed in (("pt", "point", 2), ("pl", "plane", 1), ("held", "point", 3)):
        files[name] = tmp_path / f"{name}.csv"
        assert run(capsys, "simulate", "ec66", "--kind", kind, "--poses", 40, "--seed", seed,
                   "--out", files[name])[0] == 0
    code, out, err = run(capsys, "calibrate", "ec66", files["pt"], files["pl"], "--on-plane",
                         "--lambda", 0.1, "--validate", files["held"], "--out",
                         tmp_path / "c.urdf")
    assert code == 0, err
    assert f"held-out {files['held']}, 40 samples" in out, out


def test_a_wall_along_x_keeps_its_angles_and_frames_json_reads_back(tmp_path, capsys):
    """A plane whose normal is along +-x (simulate's second wall) sits where Rx(rx) barely
    turns its normal: the fit moved plane2.rx by whole turns (-101.09 rad on seed 5), and
    `kincal evaluate` refused the FRAMES.json calibrate had just written ("beyond 100 rad
    ... a corrupted or hand-edited file?"). Frame angles are now kept within half a turn
    of their start, which is itself within a half turn of 0."""
    data, urdf, frames = tmp_path / "c.csv", tmp_path / "c.urdf", tmp_path / "f.json"
    assert run(capsys, "simulate", "ec66", "--kind", "plane", "--poses", 60, "--seed", 5,
               "--out", data)[0] == 0
    code, out, err = run(capsys, "calibrate", "ec66", data, "--on-plane", "--out", urdf,
                         "--frames-out", frames)
    assert code == 0, err
    named = json.loads(frames.read_text())["sets"][0]["frames"]
    angles = {k: v for k, v in named.items() if k.endswith((".rx", ".ry"))}
    assert abs(angles["plane2.ry"]) == pytest.approx(np.pi / 2, abs=1e-3)  # the wall
    assert max(map(abs, angles.values())) <= 2 * np.pi, angles
    code, out, err = run(capsys, "evaluate", urdf, data, "--on-plane", "--frames", frames)
    assert code == 0, err
    assert float(out.split("mean ")[1].split()[0]) < 0.05  # [mm] as the calibration's after


def test_frames_of_another_robot_are_named_so_by_evaluate_and_compensate(tmp_path, capsys):
    """UR10 frames (world -> tool0) given with EC66 data: the chain is taken from the frames
    and the load failed first, as "unknown base frame 'world' in robot 'ec66'": a frame
    the user never typed, and no word of the frames being another robot's."""
    ur, urf = tmp_path / "ur.csv", tmp_path / "ur.json"
    ec = tmp_path / "ec.csv"
    assert run(capsys, "simulate", "ur10", "--poses", 20, "--out", ur)[0] == 0
    assert run(capsys, "calibrate", "ur10", ur, "--lambda", 0.1, "--model", "complete",
               "--out", tmp_path / "ur.urdf", "--frames-out", urf)[0] == 0
    assert run(capsys, "simulate", "ec66", "--poses", 10, "--out", ec)[0] == 0
    for argv in (("evaluate", "ec66", ec, "--frames", urf),
                 ("compensate", "ec66", ec, "--frames", urf, "--out", tmp_path / "j.csv")):
        code, out, err = run(capsys, *argv)
        assert code == 1 and out == ""
        (line,) = err.strip().splitlines()
        assert line.startswith(f"kincal: error: {urf} holds frames of the robot 'ur10' "
                               "identified on the chain world -> tool0, which ec66 does not "
                               "have: frames of another robot or chain"), line
    assert not (tmp_path / "j.csv").exists()
