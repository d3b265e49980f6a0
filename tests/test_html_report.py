"""The HTML report: complete, self-contained (no network), and rendered by a real browser."""

import json
import os
import re
import signal
import struct
import subprocess
from dataclasses import replace
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from conftest import TIAGO_DIR, tiago_urdf

from kincal.cli.main import main
from kincal.errors import ExportError
from kincal.export.html_report import html_report, section_ids
from kincal.export.outputs import Outputs, write_calibration
from kincal.identification.problem import CalibrationOptions, CalibrationProblem
from kincal.models import mdh
from kincal.planning.accuracy_map import result_accuracy_map
from kincal.planning.simulation import Truth, measure, planted_table
from kincal.robot import Robot

CHROMIUM = Path("/usr/bin/chromium")


class _Page(HTMLParser):
    """Section ids, every src/href, and the tags seen."""

    def __init__(self):
        super().__init__()
        self.ids, self.links, self.tags, self.images = set(), [], set(), 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.tags.add(tag)
        if "id" in a:
            self.ids.add(a["id"])
        for key in ("src", "href", "action", "data", "poster"):
            if a.get(key) is not None:
                self.links.append(a[key])
        if tag == "img" and (a.get("src") or "").startswith("data:image/png;base64,"):
            self.images += 1


def _parse(text: str) -> _Page:
    page = _Page()
    page.feed(text)
    page.close()
    return page


def _assert_self_contained(text: str, min_images: int) -> _Page:
    page = _parse(text)
    assert set(section_ids()) <= page.ids, set(section_ids()) - page.ids
    outside = [link for link in page.links if not link.startswith(("#", "data:"))]
    assert outside == [], outside
    assert "script" not in page.tags and "link" not in page.tags and "iframe" not in page.tags
    assert "http://" not in text and "https://" not in text and "url(" not in text
    assert page.images >= min_images
    return page


@pytest.fixture(scope="module")
def result():
    rng = np.random.default_rng(3)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(30, g.n))
    truth = Truth(planted_table(model, rng), np.array([1.0, 0.2, 0.1, 0.01, 0.02, 0.3]),
                  np.array([0.03, 0.0, 0.1]), backlash={"joint_6": 0.002})
    data = measure(model, truth, q, 5e-5, rng)
    options = CalibrationOptions(n_lambdas=6, folds=3, backlash=("joint_6",))
    return CalibrationProblem(robot, data, options).solve()


@pytest.fixture(scope="module")
def page(result, tmp_path_factory):
    """(path, text) of the report of ``result``, rendered once for the tests below."""
    text = html_report(result, accuracy=result_accuracy_map(result),
                       warnings=["a <warning> & more"], notes=["export: a note"],
                       data_source="sim.csv")
    path = tmp_path_factory.mktemp("html") / "r.html"
    path.write_text(text, encoding="utf-8")
    return path, text


def test_every_section_present_and_nothing_external(result, page, tmp_path):
    text = page[1]
    # parameters, residuals per sample, per joint, CV curve, accuracy map
    _assert_self_contained(text, min_images=5)
    assert "a &lt;warning&gt; &amp; more" in text  # escaped, not markup
    for d in result.identifiability.duplicates:  # dropped and why
        assert d.describe().replace(">", "&gt;") in text
        # its table row: status dropped, and no deviation or standard error shown
        row = re.search(rf'<tr class="dropped"[^>]*><td class="name">{re.escape(d.name)}</td>'
                        r"(.*?)</tr>", text)
        cells = re.findall(r"<td[^>]*>(.*?)</td>", row.group(1))
        assert cells[0] == "dropped" and cells[2] == "" and cells[4] == ""
    assert "approached from" not in text  # (legend text is inside the PNG, not the page)
    assert "joint_6.backlash" in text and "predicted accuracy" in text
    assert text.startswith("<!DOCTYPE html>")
    path = tmp_path / "r.html"
    path.write_text("a user's file")
    with pytest.raises(ExportError, match="already exists"):
        write_calibration(result, Outputs(html=path))
    assert path.read_text() == "a user's file"


def test_evidence_choice_is_reported_where_a_result_carries_one(result):
    # the evidence estimator's result field (EvidenceFit) as the report reads it
    class Fit:
        iterations, converged = 3, True
        given, noise_given = np.array([False, False, False]), False
        log_evidence = np.array([-120.5, -118.25, -118.0])

        def line(self):
            return "prior scales length 0.3 mm; noise 0.05 mm"

    res = replace(result, lam=float("nan"))
    object.__setattr__(res, "evidence", Fit())
    section = re.search(r'<section id="cv">(.*?)</section>', html_report(res), re.S).group(1)
    assert "maximum evidence: prior scales length 0.3 mm; noise 0.05 mm" in section
    assert "-118.00" in section and "<img" not in section


def test_report_without_cv_or_map_says_so():
    rng = np.random.default_rng(5)
    robot = Robot.load("ec66")
    model = mdh.extract(robot.geometry)
    g = robot.geometry
    q = rng.uniform(np.maximum(g.lower, -np.pi), np.minimum(g.upper, np.pi), size=(20, g.n))
    truth = Truth(planted_table(model, rng), np.zeros(6), np.array([0.03, 0.0, 0.1]))
    res = CalibrationProblem(robot, measure(model, truth, q, 5e-5, rng),
                             CalibrationOptions(method="ls")).solve()
    text = html_report(res)
    _assert_self_contained(text, min_images=3)
    assert "No cross-validation in this run" in text and "No accuracy map" in text


def _png_ok(path: Path):
    """The screenshot is a PNG of the window's size and not blank."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", data[16:24])
    assert (width, height) == (1200, 6000)
    from PIL import Image  # matplotlib's own dependency

    pixels = np.asarray(Image.open(path).convert("L"))
    assert np.mean(pixels < 250) > 0.03      # ink on the page, not a white sheet
    assert len(np.unique(pixels)) > 50       # text and figures, not one flat colour
    # the figures were drawn: rows far down the page carry ink too
    assert np.mean(pixels[3000:] < 250) > 0.01


def _screenshot(html: Path, tmp_path: Path) -> Path:
    if not CHROMIUM.exists():
        pytest.skip("chromium is not installed (apt-get install chromium)")
    out = tmp_path / "shot.png"
    # its own process group, so a hung browser and its helpers can all be stopped
    proc = subprocess.Popen([str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu",
                             "--disable-background-networking", "--disable-component-update",
                             "--disable-sync", "--no-first-run",
                             f"--user-data-dir={tmp_path / 'prof'}", f"--screenshot={out}",
                             "--window-size=1200,6000", html.as_uri()],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        _, err = proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    assert proc.returncode == 0, err.decode(errors="replace")[-2000:]
    return out


def test_headless_browser_renders_the_report(page, tmp_path):
    _png_ok(_screenshot(page[0], tmp_path))


def test_cli_html_accuracy_map_report_and_plots(tmp_path):
    data = tmp_path / "rt.csv"
    assert main(["simulate", "ec66", "--out", str(data), "--poses", "30", "--seed", "2"]) == 0
    out = tmp_path / "o"
    args = ["calibrate", "ec66", str(data), "--out", str(out / "c.urdf"), "--lambda", "0.1",
            "--html", str(out / "r.html"), "--report", str(out / "r.json"),
            "--plots", str(out / "plots"), "--accuracy-map", "450", "100", "350", "200",
            "--grid", "3", "--length-unit", "mm"]
    # bad grid: one error, before solving, nothing written
    out.mkdir()  # kincal creates the plots folder itself, not missing parents
    assert main(args[:-3] + ["0", "--length-unit", "mm"]) == 1
    assert list(out.iterdir()) == []
    data_mm = tmp_path / "rt_mm.csv"
    lines = [r for r in data.read_text().splitlines() if not r.startswith("#")]
    header = lines[0].split(",")
    pos = [header.index(c) for c in ("x", "y", "z")]
    rows = [[float(v) for v in line.split(",")] for line in lines[1:]]
    for r in rows:
        for i in pos:
            r[i] *= 1e3
    data_mm.write_text(",".join(header) + "\n" + "\n".join(",".join(repr(v) for v in r)
                                                            for r in rows) + "\n")
    args[2] = str(data_mm)
    assert main(args) == 0
    report = json.loads((out / "r.json").read_text())
    amap = report["accuracy_map"]
    assert amap["reached"] + amap["skipped"] == 27 and amap["reached"] > 0
    assert 0 < amap["std_mm"]["median"] < 1.0
    assert (out / "plots" / "accuracy_map.png").stat().st_size > 10_000
    _assert_self_contained((out / "r.html").read_text(encoding="utf-8"), min_images=4)


def test_cli_analyze_accuracy_map_at_poses(tmp_path):
    data = tmp_path / "d.csv"
    assert main(["simulate", "ec66", "--out", str(data), "--poses", "30", "--seed", "4"]) == 0
    rep, plot = tmp_path / "a.json", tmp_path / "a.png"
    assert main(["analyze", "ec66", str(data), "--accuracy-poses", str(data), "--report",
                 str(rep), "--accuracy-plot", str(plot), "--noise-mm", "0.05"]) == 0
    amap = json.loads(rep.read_text())["accuracy_map"]
    assert amap["reached"] == 30 and amap["skipped"] == 0
    assert "noise 0.05 mm" in amap["covariance"] and plot.stat().st_size > 10_000
    assert main(["analyze", "ec66", str(data), "--accuracy-plot", str(tmp_path / "b.png")]) == 1
    assert main(["analyze", "ec66", str(data), "--accuracy-poses", str(data),
                 "--accuracy-map", "0.4", "0", "0.3", "0.1"]) == 1


def test_tiago_report_complete_small_and_rendered(tmp_path):
    urdf = tiago_urdf()
    out = tmp_path / "tiago.html"
    assert main(["calibrate", str(urdf), str(TIAGO_DIR / "qualisys_2021-11-30_static_postures.csv"),
                 "--tip", "wrist_ft_tool_link", "--position-columns", "x1", "y1", "z1",
                 "--method", "l2", "--out", str(tmp_path / "t.urdf"), "--html", str(out),
                 "--quiet"]) == 0
    assert out.stat().st_size < 3_000_000
    text = out.read_text(encoding="utf-8")
    _assert_self_contained(text, min_images=5)
    assert "arm_4_joint" in text  # the export note about the gimbal-locked rpy
    if CHROMIUM.exists():  # (the checks above stand without a browser)
        _png_ok(_screenshot(out, tmp_path))


def test_refused_run_report_rendered_with_its_red_box(tmp_path):
    """A refused calibration's diagnosis page, looked at in headless Chromium: rendered,
    figures drawn, and the REFUSED box (red border) at its top."""
    mm = _millimetres_as_metres(tmp_path)  # the gate refuses
    page = tmp_path / "refused.html"
    assert main(["calibrate", "ec66", str(mm), "--lambda", "0.01", "--out",
                 str(tmp_path / "c.urdf"), "--html", str(page), "-q"]) == 1
    assert not (tmp_path / "c.urdf").exists()
    _assert_self_contained(page.read_text(), 3)
    shot = _screenshot(page, tmp_path)
    _png_ok(shot)
    from PIL import Image

    rgb = np.asarray(Image.open(shot).convert("RGB")).astype(int)[:900]
    red = (rgb[..., 0] > 150) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60)
    assert red.sum() > 2000  # the box's border and heading


def test_the_gates_warnings_are_in_the_page(tmp_path):
    """The page's 'Warnings and notes' lacked what the gate said on the console: an
    accepted implausible result ('accepted an implausible calibration as asked') and the
    gate's notes (a whole robot's log: columns of joints off the chain ignored)."""
    mm = _millimetres_as_metres(tmp_path)  # implausible
    page = tmp_path / "accepted.html"
    assert main(["calibrate", "ec66", str(mm), "--lambda", "0.01", "--out",
                 str(tmp_path / "c.urdf"), "--html", str(page), "-q",
                 "--accept-implausible"]) == 0
    text = page.read_text()
    warned = text[text.index('id="warnings"'):text.index('id="provenance"')]
    assert "warning: accepted an implausible calibration as asked" in warned


def test_held_out_caption_speaks_of_axes_only_where_there_are_some():
    """A flush file's held-out table (heights and tilts) has no per-axis rows; its caption
    explained them anyway ('Per axis: root mean square of the residual component in the
    measurement frame'), there being no measurement frame either."""
    from kincal.export.html_run import validation_section
    from kincal.export.validation import Validation

    z = np.zeros((3, 3))
    flush = Validation("held.csv", "flush", np.arange(3), z, z, np.ones(3), np.ones(3), False)
    point = replace(flush, kind="point", per_axis=True)
    assert "Per axis" not in validation_section([flush])
    assert "Per axis" in validation_section([point])


def _millimetres_as_metres(tmp_path):
    """A simulated EC66 point file with its positions in millimetres (read as metres)."""
    import csv

    data = tmp_path / "cal.csv"
    assert main(["simulate", "ec66", "--out", str(data), "--poses", "30", "--seed", "2"]) == 0
    rows = list(csv.DictReader(line for line in data.open() if not line.startswith("#")))
    mm = tmp_path / "mm.csv"
    with mm.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows({**r, **{k: str(float(r[k]) * 1000) for k in "xyz"}} for r in rows)
    return mm
