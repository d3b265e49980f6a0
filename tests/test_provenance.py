"""Provenance in every file a calibration writes, and a refused run's diagnosis."""

import csv
import hashlib
import json
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from PIL import Image

from kincal import __version__
from kincal.cli.main import main
from kincal.export.provenance import Provenance, FileHash, stamp_urdf
from kincal.frames_file import CellFrames

EPOCH, STAMP = "1700000000", "2023-11-14T22:13:20Z"
EC66 = Path(__file__).resolve().parents[1] / "urdf" / "ec66.urdf"


def _sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One calibration writing every output, at a fixed SOURCE_DATE_EPOCH."""
    d = tmp_path_factory.mktemp("prov")
    mp = pytest.MonkeyPatch()
    mp.setenv("SOURCE_DATE_EPOCH", EPOCH)
    try:
        assert main(["simulate", "ec66", "--out", str(d / "cal.csv"), "--poses", "30",
                     "--seed", "5", "--tool-m", "0.03", "0.02", "0.1"]) == 0
        argv = ["calibrate", str(EC66), str(d / "cal.csv"), "--tip", "flange",
                "--lambda", "0.01", "--out", str(d / "c.urdf"), "--frames-out",
                str(d / "f.json"), "--report", str(d / "r.json"), "--html", str(d / "r.html"),
                "--yaml-out", str(d / "k.yaml"), "--mdh-out", str(d / "m.csv"),
                "--plots", str(d / "p"), "--residuals-out", str(d / "res.csv"), "--quiet"]
        assert main(argv) == 0
    finally:
        mp.undo()
    return d, argv


def _lines_ok(text: str, d: Path, argv) -> None:
    """The provenance lines, in whatever comment syntax: version, time, command, hashes,
    verdict."""
    assert f"made by kincal {__version__} at {STAMP}" in text
    assert f"sha256 {_sha(EC66)}" in text and f"sha256 {_sha(d / 'cal.csv')}" in text
    assert "plausibility gate: plausible (no finding)" in text
    assert "calibrate" in text and "c.urdf" in text


def test_urdf_comment(run):
    d, argv = run
    text = (d / "c.urdf").read_text()
    root = ET.fromstring(text.encode())  # still well-formed XML: no "--" in the comment
    assert root.tag == "robot"
    comment = text[text.index("<!-- made by kincal"):]
    comment = comment[:comment.index("-->")]
    _lines_ok(comment, d, argv)
    assert "-\\-out" in comment and "--" not in comment[4:]
    # everything else of the nominal file is kept: its own comment comes next
    assert "Elite Robots EC66" in text[text.index("-->"):]


def test_json_files(run):
    d, argv = run
    for name in ("f.json", "r.json"):
        prov = json.loads((d / name).read_text())["provenance"]
        assert prov["kincal_version"] == __version__ and prov["created_utc"] == STAMP
        assert prov["command"].startswith("kincal calibrate ") and "--frames-out" in prov["command"]
        assert prov["robot"]["sha256"] == _sha(EC66)
        assert prov["robot"]["urdf_text_sha256"] == _sha(EC66)  # a URDF is parsed as read
        assert prov["data"] == [{"path": str(d / "cal.csv"), "sha256": _sha(d / "cal.csv")}]
        assert prov["gate"]["verdict"] == "plausible"
    # FRAMES.json with its provenance still reads back and serves evaluate
    frames = CellFrames.read(d / "f.json")
    assert frames.tip_frame == "flange"
    assert main(["evaluate", str(d / "c.urdf"), str(d / "cal.csv"), "--frames",
                 str(d / "f.json")]) == 0


def test_yaml_csv_html_and_plots(run):
    d, argv = run
    from kincal.measurements.csv_table import read_columns

    for name in ("k.yaml", "m.csv", "res.csv"):
        head = [line for line in (d / name).read_text().splitlines() if line.startswith("#")]
        _lines_ok("\n".join(head), d, argv)
    # the residual CSV under its # lines: kincal's one CSV reader reads its numbers
    table = read_columns(d / "res.csv", ["row", "error_m", "r1", "r2", "r3"])
    assert len(table.values["error_m"]) == 30 and table.lines[0] == 9  # title + 7 lines + header
    assert table.header[:6] == ("split", "set", "source", "kind", "row", "error_m")
    html = (d / "r.html").read_text()
    assert 'id="provenance"' in html
    _lines_ok(html[html.index('id="provenance"'):], d, argv)
    pngs = sorted((d / "p").glob("*.png"))
    assert pngs
    report = json.loads((d / "r.json").read_text())["provenance"]
    for png in pngs:
        info = Image.open(png).text
        assert info["Software"] == f"kincal {__version__}"
        assert info["Creation Time"] == STAMP
        _lines_ok(info["Comment"], d, argv)
        # the PNG keywords and the JSON object the JSON files carry, for programs
        assert info["Source"] == report["command"] and "--plots" in info["Source"]
        assert info["Description"] == (f"made by kincal {__version__} from robot {EC66} "
                                       f"and data {d / 'cal.csv'}; plausibility gate: plausible")
        assert json.loads(info["kincal-provenance"]) == report


def test_banner_of_a_generator_is_dropped_and_the_rest_kept():
    prov = Provenance(__version__, STAMP, "kincal calibrate a --out b", FileHash("r.urdf", "ab"),
                      "cd", (), (FileHash("d.csv", "ef"),), "plausible", "no finding")
    banner = ('<?xml version="1.0"?>\n'
              "<!-- ============================================================== -->\n"
              "<!-- |    This document was autogenerated by xacro from ur.xacro  | -->\n"
              "<!-- |    EDITING THIS FILE BY HAND IS NOT RECOMMENDED            | -->\n"
              "<!-- ============================================================== -->\n")
    body = '<robot name="r">\n  <!-- autogenerated by nobody: kept, not a banner -->\n</robot>\n'
    out = stamp_urdf(banner + body, prov)
    assert "EDITING THIS FILE" not in out and "This document was" not in out
    assert out.startswith('<?xml version="1.0"?>\n<!-- made by kincal')
    assert out.endswith(body)  # the rest byte for byte
    # a first comment that is not a generator's is kept, byte for byte
    own = '<?xml version="1.0"?>\n<!-- my robot, measured 2024 -->\n' + body
    out = stamp_urdf(own, prov)
    assert out.endswith("<!-- my robot, measured 2024 -->\n" + body)
    # CRLF files stay CRLF
    crlf = stamp_urdf((banner + body).replace("\n", "\r\n"), prov)
    assert "\n" not in crlf.replace("\r\n", "") and "autogenerated by xacro" not in crlf


def test_bad_source_date_epoch_is_one_line(tmp_path, capsys, monkeypatch):
    assert main(["simulate", "ec66", "--out", str(tmp_path / "cal.csv"), "--poses", "30",
                 "--seed", "5"]) == 0
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "yesterday")
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(tmp_path / "cal.csv"), "--lambda", "0.01",
                 "--out", str(tmp_path / "c.urdf"), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SOURCE_DATE_EPOCH" in err[0] and err[0].startswith("kincal: error:")
    assert not (tmp_path / "c.urdf").exists()


def test_refused_run_writes_the_diagnosis_only(run, tmp_path, capsys):
    d, _ = run
    rows = list(csv.DictReader(line for line in (d / "cal.csv").open()
                               if not line.startswith("#")))
    with (tmp_path / "mm.csv").open("w", newline="") as f:  # millimetres, read as metres
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, **{k: str(float(r[k]) * 1000) for k in "xyz"}})
    out = {k: tmp_path / v for k, v in (("urdf", "c.urdf"), ("frames", "f.json"),
                                         ("report", "r.json"), ("html", "r.html"),
                                         ("yaml", "k.yaml"), ("mdh", "m.csv"))}
    capsys.readouterr()
    code = main(["calibrate", str(EC66), str(tmp_path / "mm.csv"), "--tip", "flange",
                 "--lambda", "0.01", "--out", str(out["urdf"]), "--frames-out",
                 str(out["frames"]), "--report", str(out["report"]), "--html", str(out["html"]),
                 "--yaml-out", str(out["yaml"]), "--mdh-out", str(out["mdh"]),
                 "--plots", str(tmp_path / "p")])
    cap = capsys.readouterr()
    assert code == 1
    for k in ("urdf", "frames", "yaml", "mdh"):
        assert not out[k].exists(), k
    errors = [line for line in cap.err.splitlines() if line.startswith("kincal: error:")]
    assert len(errors) == 1 and "REFUSED" in errors[0] and str(out["html"]) in errors[0]
    assert f"REFUSED calibration: {out['html']}" in cap.out  # the console says where
    report = json.loads(out["report"].read_text())
    assert report["refused"]["verdict"] == "REFUSED"
    assert report["provenance"]["gate"]["verdict"] == "REFUSED"
    assert report["plausibility"]["plausible"] is False
    assert "millimetres read as metres" in report["refused"]["message"]
    html = out["html"].read_text()
    assert "<title>REFUSED: " in html and 'id="refused"' in html
    assert "millimetres read as metres" in html  # the gate's evidence on the page
    pngs = sorted((tmp_path / "p").glob("*.png"))
    assert pngs and all("plausibility gate: REFUSED" in Image.open(p).text["Comment"]
                        for p in pngs)


def test_refused_run_without_diagnosis_writes_nothing(run, tmp_path, capsys):
    d, _ = run
    text = (d / "cal.csv").read_text().splitlines()
    rows = list(csv.DictReader(line for line in text if not line.startswith("#")))
    with (tmp_path / "mm.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({**r, **{k: str(float(r[k]) * 1000) for k in "xyz"}})
    assert main(["calibrate", str(EC66), str(tmp_path / "mm.csv"), "--tip", "flange",
                 "--lambda", "0.01", "--out", str(tmp_path / "c.urdf")]) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mm.csv"]
    assert "nothing is written" in capsys.readouterr().err


# ------------------------------------------------ the other commands' files (verdict: no gate)
def _no_gate_lines(text: str, *, robot: Path, data=(), command: str) -> None:
    """The provenance lines of a file no gate stands in front of."""
    assert f"made by kincal {__version__} at {STAMP}" in text
    # the robot by its hash (a bundled name resolves to the installed copy's path)
    assert any(line.removeprefix("# ").startswith("robot: ")
               and line.endswith(f" sha256 {_sha(robot)}")
               for line in text.splitlines())
    for f in data:
        assert f"data: {f} sha256 {_sha(f)}" in text, f
    assert "plausibility gate: no gate" in text
    assert f"command: kincal {command}" in text


def _comments(path: Path) -> str:
    """The # lines a CSV kincal wrote starts with (the header line follows them)."""
    lines = path.read_text().splitlines()
    head = [line for line in lines if line.startswith("#")]
    assert lines[:len(head)] == head and not lines[len(head)].startswith("#")
    return "\n".join(head)


@pytest.fixture
def epoch(monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", EPOCH)


def test_simulate_files_carry_it_and_read_back(run, tmp_path, epoch):
    d, _ = run
    # the fixture's data came from simulate too, and calibrate read it as written
    _no_gate_lines(_comments(d / "cal.csv"), robot=EC66, command="simulate ec66")
    out, truth = tmp_path / "s.csv", tmp_path / "t.json"
    assert main(["simulate", "ec66", "--out", str(out), "--poses", "12", "--truth-out",
                 str(truth)]) == 0
    _no_gate_lines(_comments(out), robot=EC66, command=f"simulate ec66 --out {out}")
    prov = json.loads(truth.read_text())["provenance"]
    assert prov["gate"] == {"verdict": "no gate",
                            "findings": "no plausibility gate applies to this output"}
    assert prov["robot"]["sha256"] == _sha(EC66) and prov["created_utc"] == STAMP
    # plan's CSV, read back by simulate --poses-file, with the files plan read in its header
    poses = tmp_path / "poses.csv"
    assert main(["plan", str(EC66), "--tip", "flange", "--random", "200", "--poses", "8",
                 "--measured", str(out), "--out", str(poses)]) == 0
    _no_gate_lines(_comments(poses), robot=EC66, data=[out], command=f"plan {EC66}")
    again = tmp_path / "again.csv"
    assert main(["simulate", "ec66", "--poses-file", str(poses), "--out", str(again)]) == 0
    _no_gate_lines(_comments(again), robot=EC66, data=[poses], command="simulate")


def test_evaluate_analyze_and_compensate_files_carry_it(run, tmp_path, epoch):
    d, _ = run
    cal, urdf, frames = d / "cal.csv", d / "c.urdf", d / "f.json"
    assert main(["evaluate", str(urdf), str(cal), "--frames", str(frames), "--report",
                 str(tmp_path / "e.json")]) == 0
    prov = json.loads((tmp_path / "e.json").read_text())["provenance"]
    assert prov["robot"] == {"path": str(urdf), "sha256": _sha(urdf),
                             "urdf_text_sha256": _sha(urdf), "xacro_args": {}}
    assert prov["data"] == [{"path": str(cal), "sha256": _sha(cal)},
                            {"path": str(frames), "sha256": _sha(frames)}]
    assert prov["gate"]["verdict"] == "no gate" and prov["command"].startswith("kincal evaluate")
    assert main(["analyze", str(EC66), str(cal), "--tip", "flange", "--report",
                 str(tmp_path / "a.json"), "--accuracy-map", "0.4", "0", "0.3", "0.2",
                 "--accuracy-plot", str(tmp_path / "a.png")]) == 0
    prov = json.loads((tmp_path / "a.json").read_text())["provenance"]
    assert prov["data"] == [{"path": str(cal), "sha256": _sha(cal)}]
    info = Image.open(tmp_path / "a.png").text
    assert info["Software"] == f"kincal {__version__}" and info["Creation Time"] == STAMP
    _no_gate_lines(info["Comment"], robot=EC66, data=[cal], command=f"analyze {EC66}")
    png = json.loads(info["kincal-provenance"])
    assert png == prov and png["command"] == info["Source"]  # the JSON report's own
    assert png["data"] == [{"path": str(cal), "sha256": _sha(cal)}]
    out = tmp_path / "j.csv"
    assert main(["compensate", str(urdf), "--program", str(cal), "--nominal", str(EC66),
                 "--frames", str(frames), "--tip", "flange", "--out", str(out)]) == 0
    _no_gate_lines(_comments(out), robot=urdf, data=[cal, EC66, frames],
                   command=f"compensate {urdf}")


def test_fleet_files_carry_it_and_read_back(run, tmp_path, epoch):
    from kincal.identification.prior import read_prior

    d, _ = run
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for f, seed in ((a, "1"), (b, "2")):
        assert main(["simulate", "ec66", "--out", str(f), "--poses", "30", "--seed", seed,
                     "--tool-m", "0.03", "0.02", "0.1"]) == 0
    out = tmp_path / "fleet"
    assert main(["fleet", str(EC66), str(a), str(b), "--tip", "flange", "--out-dir", str(out),
                 "-q"]) == 0
    for name in ("FLEET_SUMMARY.json", "FLEET.json"):
        prov = json.loads((out / name).read_text())["provenance"]
        assert prov["command"].startswith(f"kincal fleet {EC66} {a} {b}")
        assert [x["sha256"] for x in prov["data"]] == [_sha(a), _sha(b)]
        assert prov["gate"]["verdict"] == "per unit"
        assert prov["gate"]["findings"].startswith("each unit's own gate: 2 calibrated, 0 refused")
    assert read_prior(out / "FLEET.json").n_units == 2  # the prior still reads back
    html = (out / "fleet.html").read_text()
    section = html[html.index('id="provenance"'):html.index("</body>")]
    assert f"sha256 {_sha(a)}" in section and "plausibility gate: per unit" in section
    unit = (out / "a" / "corrected.urdf").read_text()  # a unit's files: its own gate
    assert "command: kincal fleet" in unit and "plausibility gate: plausible" in unit
    assert f"data: {a} sha256 {_sha(a)}" in unit


def test_a_format_without_a_stamp_is_refused():
    from kincal.errors import ExportError

    prov = Provenance.of_run()
    assert prov.robot.path == "(no robot)" and prov.command is None
    with pytest.raises(ExportError, match="no provenance stamp"):
        prov.stamp("docx", "text")
    with pytest.raises(ExportError, match="without </body>"):
        prov.stamp("html", "<p>no body</p>")
    with pytest.raises(ExportError, match="given as a dict"):
        prov.stamp("json", "[1, 2]")


# ------------------------------------------------ the public plot functions' PNG files
def _png_provenance(path: Path) -> dict:
    info = Image.open(path).text
    prov = json.loads(info["kincal-provenance"])
    assert info["Software"] == f"kincal {prov['kincal_version']}"
    assert info["Creation Time"] == prov["created_utc"]
    return prov


def test_plot_functions_write_their_provenance(run, tmp_path, epoch):
    from kincal.errors import ExportError
    from kincal.export import plots
    from kincal.export.diagnostic_plots import plot_residuals_by_joint, plot_residuals_per_pose
    from kincal.identification.problem import calibrate
    from kincal.measurements.data import Measurements
    from kincal.robot import Robot

    d, _ = run
    cal = d / "cal.csv"
    curve = ([1e-3, 1e-2, 1e-1], [0.3, 0.2, 0.25], 1e-2)
    # plain arrays: this kincal and the Python API, no input file named
    plain = plots.plot_cv_curve(*curve, tmp_path / "cv.png")
    prov = _png_provenance(plain)
    assert prov["kincal_version"] == __version__ and prov["created_utc"] == STAMP
    assert prov["command"] is None and prov["data"] == []
    assert prov["robot"]["sha256"] is None and prov["gate"]["verdict"] == "no gate"
    assert Image.open(plain).text["Source"] == "kincal (Python API)"
    # a Provenance given: its inputs and their hashes
    robot = Robot.load(str(EC66), tip="flange")
    given = Provenance.of_run(robot, [cal], command=["my_script.py", "--fast"])
    plots.plot_error_distributions([("after", [0.1, 0.2, 0.15])], tmp_path / "e.png",
                                   source=given)
    prov = _png_provenance(tmp_path / "e.png")
    assert prov == given.as_dict() and prov["command"] == "my_script.py --fast"
    assert prov["robot"]["sha256"] == _sha(EC66)
    assert prov["data"] == [{"path": str(cal), "sha256": _sha(cal)}]
    # a result's figures: its robot and data files, read by hash
    result = calibrate(robot, Measurements.from_csv(cal, robot.joint_names), lam=0.01)
    for plot, name in ((plot_residuals_per_pose, "pose.png"), (plot_residuals_by_joint, "j.png")):
        assert plot(result, tmp_path / name) == (tmp_path / name).resolve()
        prov = _png_provenance(tmp_path / name)
        assert prov["robot"]["path"] == str(EC66) and prov["robot"]["sha256"] == _sha(EC66)
        assert prov["data"] == [{"path": str(cal), "sha256": _sha(cal)}]
        assert prov["gate"]["verdict"] == "no gate"  # no gate stands before a plot function
    # a file never goes out with bare text fields instead of a provenance; bytes may
    with pytest.raises(ExportError, match="carries a Provenance"):
        plots.plot_cv_curve(*curve, tmp_path / "x.png", source="my tool")
    assert not (tmp_path / "x.png").exists()
    png = plots.plot_cv_curve(*curve, None, source="my tool")
    (tmp_path / "bytes.png").write_bytes(png)
    assert Image.open(tmp_path / "bytes.png").text == {"Software": "my tool"}


def test_simulated_fleet_files_carry_it_and_read_back(tmp_path, epoch):
    import numpy as np

    from kincal.errors import ExportError
    from kincal.fleet.simulated import FleetModel
    from kincal.measurements.data import Measurements
    from kincal.robot import Robot

    robot = Robot.load("ec66", tip="flange")
    fm = FleetModel.of(robot, 0)
    paths = fm.tracker_files(tmp_path, 2, np.random.default_rng(1), n=12)
    rng = np.random.default_rng(1)  # the same units, made again in memory
    for path in map(Path, paths):
        head = _comments(path)
        assert f"made by kincal {__version__} at {STAMP}" in head
        assert f"robot: {robot.source} sha256 {_sha(robot.source)}" in head
        assert "command: (Python API)" in head and "plausibility gate: no gate" in head
        made = fm.tracker(fm.unit(rng), rng, n=12)
        read = Measurements.from_csv(path, robot.joint_names)  # kincal's reader skips them
        assert np.array_equal(read.joint_values, made.joint_values)
        assert np.array_equal(read.positions, made.positions)
    before = [Path(p).read_bytes() for p in paths]
    with pytest.raises(ExportError, match="already exists"):
        fm.tracker_files(tmp_path, 2, np.random.default_rng(5), n=12)
    assert [Path(p).read_bytes() for p in paths] == before  # all or none, never replaced


def test_report_pieces_are_the_report_text_byte_for_byte(tmp_path, capsys):
    """REPORT.json is written in pieces (the encoder's tokens joined about 64 KB at a time,
    each array made Python numbers as it is reached: a 300,000-pose report took 909 MB made
    at once): the same bytes as the text made whole, numpy numbers, NaN (null) and nested
    arrays included."""
    import numpy as np

    from kincal.export.report import dump_pieces, dumps, result_dict, result_tree
    from kincal.identification.problem import CalibrationOptions, CalibrationProblem
    from kincal.measurements.sets import read_set_file
    from kincal.robot import Robot

    data = tmp_path / "p.csv"
    assert main(["simulate", "ec66", "--poses", "40", "--out", str(data)]) == 0
    robot = Robot.load("ec66")
    result = CalibrationProblem(robot, read_set_file(data, robot.joint_names),
                                CalibrationOptions(method="ls")).solve()
    content = result_dict(result)
    content["extra"] = {"nan": np.float64("nan"), "inf": float("inf"),
                        "array": np.arange(6.0).reshape(2, 3), "int": np.int64(3)}
    whole = dumps(content)
    pieces = list(dump_pieces(content, size=256))
    assert len(pieces) > 10 and all(pieces)
    assert "".join(pieces) == whole
    assert json.loads(whole)["extra"] == {"nan": None, "inf": None,
                                          "array": [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]], "int": 3}
    # the tree with its numpy arrays kept (each made Python numbers as it is written): the
    # same bytes again, NaN in an array included
    tree = result_tree(result)
    tree["extra"] = dict(content["extra"], array=np.array([[0.0, np.nan], [np.inf, 1.5]]))
    content["extra"]["array"] = [[0.0, None], [None, 1.5]]
    assert any(isinstance(v, np.ndarray) for v in tree["residuals"].values())
    assert "".join(dump_pieces(tree, size=256)) == dumps(content)


PROLOGS = {  # how URDF files begin, each of them read by urdfdom and Python's XML parser
    "byte-order mark": '\ufeff<?xml version="1.0" encoding="utf-8"?>\n<!-- mine -->\n',
    "declaration over two lines": '<?xml version="1.0"\n      encoding="utf-8"?>\n',
    "processing instruction": '<?xml version="1.0"?>\n<?xml-model href="urdf.xsd"?>\n',
    "comment on the declaration's line": '<?xml version="1.0"?><!-- my\n robot -->\n',
    "root on the declaration's line": '<?xml version="1.0"?><robot name="r"\n>'}


@pytest.mark.parametrize("case", sorted(PROLOGS))
def test_provenance_comment_leaves_the_urdf_readable(case):
    """The comment went after the first line: inside a two-line declaration or a comment
    begun there, before a processing instruction (urdfdom's TinyXML-2 refuses the file),
    before a byte-order mark (which then stood in the middle of the file)."""
    import pinocchio as pin

    prov = Provenance(__version__, STAMP, "kincal calibrate a --out b", FileHash("r.urdf", "ab"),
                      "cd", (), (FileHash("d.csv", "ef"),), "plausible", "no finding")
    body = ('<link name="a"/><joint name="j" type="revolute"><parent link="a"/>'
            '<child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" '
            'velocity="1"/></joint><link name="b"/></robot>\n')
    text = PROLOGS[case] + ("" if case.startswith("root") else '<robot name="r">') + body
    pin.buildModelFromXML(text)  # the original is read
    out = stamp_urdf(text, prov)
    assert out.count("<!-- made by kincal") == 1
    assert out.replace(prov.xml_comment() + "\n", "") == text  # nothing else changed
    assert ET.fromstring(out.encode("utf-8")).get("name") == "r"
    assert pin.buildModelFromXML(out).names[1] == "j"
    assert out.startswith(PROLOGS[case].split("<!--")[0].split("<robot")[0].rstrip("\n"))


def test_calibrated_urdf_with_a_byte_order_mark_loads(tmp_path):
    """A URDF saved with a byte-order mark (Windows editors) was written with the comment
    before the mark and the XML declaration: not XML, refused by every URDF reader."""
    from kincal.robot import Robot

    urdf = tmp_path / "bom.urdf"
    urdf.write_text(EC66.read_text(encoding="utf-8"), encoding="utf-8-sig")
    assert main(["simulate", "ec66", "--out", str(tmp_path / "d.csv"), "--poses", "30",
                 "--seed", "5", "--quiet"]) == 0
    assert main(["calibrate", str(urdf), str(tmp_path / "d.csv"), "--tip", "flange",
                 "--lambda", "0.01", "--out", str(tmp_path / "c.urdf"), "--quiet"]) == 0
    data = (tmp_path / "c.urdf").read_bytes()
    assert data.startswith(b'\xef\xbb\xbf<?xml version="1.0" encoding="utf-8"?>\n<!-- made by')
    ET.fromstring(data)
    assert Robot.load(tmp_path / "c.urdf", tip="flange").joint_names[0] == "joint_1"


def test_a_data_file_name_of_undecoded_bytes_and_control_characters(tmp_path):
    """A data file named in Latin-1 on a UTF-8 system (its byte 0xe4 held by Python as a lone
    surrogate) crashed every writer of its name (UnicodeEncodeError); a control character
    in it went into the URDF's comment, which no XML parser then read."""
    import os

    from kincal.robot import Robot

    data = tmp_path / os.fsdecode(b"m\xe4rz\x01.csv")
    assert main(["simulate", "ec66", "--out", str(data), "--poses", "30", "--seed", "5",
                 "--quiet"]) == 0
    out = {k: tmp_path / f"c.{k}" for k in ("urdf", "html", "csv")}
    assert main(["calibrate", str(EC66), str(data), "--tip", "flange", "--lambda", "0.01",
                 "--out", str(out["urdf"]), "--html", str(out["html"]),
                 "--residuals-out", str(out["csv"]), "--quiet"]) == 0
    shown = "m\\xe4rz\\x01.csv"
    text = out["urdf"].read_text(encoding="utf-8")
    assert f"data: {tmp_path}/{shown} sha256 {_sha(data)}" in text
    ET.fromstring(text.encode("utf-8"))
    assert Robot.load(out["urdf"], tip="flange").joint_names[-1] == "joint_6"
    assert shown in out["html"].read_text(encoding="utf-8")
    rows = [r for r in out["csv"].read_text(encoding="utf-8").splitlines()
            if not r.startswith("#")]
    assert rows[1].split(",")[2] == f"{tmp_path}/{shown}"
