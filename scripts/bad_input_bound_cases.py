"""The bad-input sweep's cases for the numeric options' bounds: values far beyond a robot
cell (a kilometre cube, a tolerance or a penalty no data set can answer, 10^9 rounds), each
refused with one line naming the option, the value and the range, nothing written.

Used by scripts/bad_input_sweep.py; argv use its placeholders {d} (the case's folder),
{csv} (a good point file), {poses} (a good pose file), {urdf} (a corrected URDF) and
{frames} (its FRAMES.json).
"""

from __future__ import annotations


def bound_cases():
    """(label, argv) of numeric options beyond their accepted range: exit code 1."""
    cal = ["calibrate", "ec66", "{csv}", "--out", "{d}/o.urdf"]
    an = ["analyze", "ec66", "{csv}", "--report", "{d}/a.json"]
    plan = ["plan", "ec66", "--random", "40", "--poses", "10", "--out", "{d}/p.csv"]
    volume = plan + ["--in-cube", "0.5", "0", "0.3", "0.3"]
    sim = ["simulate", "ec66", "--out", "{d}/s.csv", "--poses", "5"]
    comp = ["compensate", "{urdf}", "{csv}", "--tip", "flange", "--frames", "{frames}",
            "--out", "{d}/j.csv"]
    fleet = ["fleet", "ec66", "{csv}", "{poses}", "--out-dir", "{d}/F"]
    table = [
        (comp, "--tolerance-mm", [["1e308"], ["1e7"], ["11"], ["1e-300"]]),
        (comp, "--point", [["0"], ["-1"]]),
        (cal, "--lambda", [["1e308"], ["1e13"]]),
        (fleet, "--lambda", [["1e308"]]),
        (cal + ["--robust", "huber"], "--robust-scale-mm", [["1e308"], ["1e7"], ["1e-300"]]),
        (cal, "--folds", [["3000"]]),
        (cal, "--set-sigma-mm", [["0"], ["1e308"]]),
        (cal, "--accuracy-map", [["0.5", "0", "0.3", "1e308"], ["0.5", "0", "0.3", "2000"],
                                 ["1e308", "0", "0.3", "0.2"]]),
        (an, "--accuracy-map", [["0.5", "0", "0.3", "1e7"], ["500", "0", "3e6", "200"]]),
        (an + ["--length-unit", "mm"], "--accuracy-map", [["500", "0", "300", "2e6"]]),
        (plan, "--in-cube", [["0.5", "0", "0.3", "2000"], ["1e308", "0", "0.3", "0.3"]]),
        (plan, "--in-sphere", [["0.5", "0", "0.3", "1e308"]]),
        (plan + ["--length-unit", "mm"], "--in-sphere", [["500", "0", "300", "2e6"]]),
        (volume + ["--criterion", "i"], "--target-cube", [["0.5", "0", "0.3", "1e308"]]),
        (volume, "--floor", [["1e308"], ["-1500"]]),
        (plan + ["--kind", "distance"], "--pivot", [["0", "1e308", "0"], ["0", "2000", "0"]]),
        (sim, "--in-sphere", [["0.5", "0", "0.3", "1e308"], ["0.5", "0", "0.3", "5000"]]),
        (sim, "--base-frame", [["0.8", "0.3", "-0.2", "1", "900", "60"],
                               ["0.8", "3000", "-0.2", "1", "2", "60"]]),
        (fleet, "--hierarchical", [["1000000000"], ["101"]]),
        (fleet, "--tool-offset", [["0", "1e308", "0"]]),
    ]
    for base, option, values in table:
        for v in values:
            yield f"{base[0]} {option} {' '.join(v)} (beyond its range)", base + [option, *v]
