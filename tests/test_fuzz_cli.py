"""Hypothesis-driven fuzzing of CSV content and CLI options through ``main([...])``.

The promise checked on every example: exit code 0, 1 (a KincalError: exactly one line
``kincal: error: ...``) or 2 (an argparse usage error); never a traceback or another
exception; and when the run fails, the folder is exactly as before (names, bytes, mtimes).
"""

import os
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_faults import snapshot

from kincal.cli.main import main

JOINTS = [f"joint_{i}" for i in range(1, 7)]
# KINCAL_FUZZ_EXAMPLES=500 explores further, with fresh random examples on every run
EXAMPLES = int(os.environ.get("KINCAL_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=EXAMPLES, deadline=None, derandomize=EXAMPLES == 25,
                    suppress_health_check=[HealthCheck.too_slow,
                                           HealthCheck.function_scoped_fixture])

GOOD_ROW = ["0.1", "-0.4", "1.2", "0.3", "-1.1", "0.5", "0.41", "0.02", "0.33"]
CELLS = st.one_of(
    st.sampled_from(["", " ", "nan", "NaN", "inf", "-inf", "1e999", "0x10", "1,5", '"3"', "'",
                     "1e-320", "--1", "１", "\t", "12 34", "None", "true", "0"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=6),
)


def _promise(argv, folder: Path, capsys) -> int:
    """Run main(argv) and check the promise; return the exit code."""
    before = snapshot(folder)
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: usage error
        code = exc.code
        assert code == 2, code
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert not any("Traceback" in e for e in err), err
    if code == 1:
        assert len([e for e in err if e.startswith("kincal: error:")]) == 1, err
    elif code == 2:
        assert err and "error:" in err[-1], err
    else:
        assert code == 0, code
    if code != 0:
        assert snapshot(folder) == before
    return code


@st.composite
def csv_texts(draw):
    header = list(JOINTS) + ["x", "y", "z"]
    if draw(st.booleans()):  # damage the header
        k = draw(st.integers(0, len(header) - 1))
        header[k] = draw(st.sampled_from(["", "joint_1", "jiont_3", "x ", "X", header[k] + "2"]))
    rows = []
    for _ in range(draw(st.integers(0, 12))):
        row = list(GOOD_ROW)
        for _ in range(draw(st.integers(0, 3))):
            k = draw(st.integers(0, len(row)))
            if k == len(row):
                row.append(draw(CELLS))
            else:
                row[k] = draw(CELLS)
        rows.append(row)
    sep = draw(st.sampled_from(["\n", "\r\n"]))
    text = sep.join(",".join(r) for r in [header] + rows)
    if draw(st.booleans()):
        text = draw(st.sampled_from(["\ufeff", "", "\x00", "# comment\n"])) + text
    return text


@SETTINGS
@given(text=csv_texts())
def test_fuzzed_csv_keeps_the_promise(text, capsys):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "data.csv").write_text(text, encoding="utf-8", errors="surrogatepass")
        _promise(["calibrate", "ec66", str(folder / "data.csv"), "--method", "frames",
                  "--out", str(folder / "out.urdf"), "--report", str(folder / "r.json")],
                 folder, capsys)


NUMBERS = st.sampled_from(["nan", "inf", "-inf", "-1", "0", "1", "2", "0.5", "1e308", "-0",
                           "99999999999999999999", "abc", ""])
OPTIONS = {
    "calibrate": ["--lambda", "--folds", "--seed", "--robust-scale-mm", "--tool-offset",
                  "--method", "--robust", "--fix", "--free", "--backlash", "--order-column",
                  "--length-unit"],
    "simulate": ["--poses", "--size-mm", "--tilt-deg", "--noise-mm", "--seed", "--truth-seed",
                 "--length-error-mm", "--angle-error-deg", "--tool-m", "--center-m",
                 "--tool-offset"],
    "plan": ["--poses", "--random", "--seed", "--noise-mm", "--tool-offset"],
}
ARITY = {"--tool-offset": 3, "--tool-m": 3, "--center-m": 3}
WORDS = {"--method": ["l2", "ls", "frames", "lq"], "--robust": ["huber", "cauchy", "l1"],
         "--fix": ["joint_2.a", "base.x", "*"], "--free": ["joint_2.d", "nope"],
         "--backlash": ["joint_6", "joint_9"], "--order-column": ["t", "x"],
         "--length-unit": ["m", "mm", "cm"]}


@st.composite
def option_lists(draw, command):
    argv = []
    for option in draw(st.lists(st.sampled_from(OPTIONS[command]), max_size=4, unique=True)):
        if option in WORDS:
            argv += [option, draw(st.sampled_from(WORDS[option]))]
        else:
            argv += [option] + [draw(NUMBERS) for _ in range(ARITY.get(option, 1))]
    return argv


@pytest.fixture(scope="module")
def small_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("fuzz")
    assert main(["simulate", "ec66", "--out", str(d / "cal.csv"), "--poses", "12",
                 "--tool-m", "0.03", "0.02", "0.12"]) == 0
    return d / "cal.csv"


@SETTINGS
@given(data=st.data())
def test_fuzzed_options_keep_the_promise(data, small_csv, capsys):
    command = data.draw(st.sampled_from(sorted(OPTIONS)))
    options = data.draw(option_lists(command))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if command == "calibrate":
            # a fixed lambda and plain frames keep each example quick when it is valid
            argv = ["calibrate", "ec66", str(small_csv), "--out", str(folder / "o.urdf")]
            if not {"--lambda", "--method"} & set(options):
                # no CV sweep (seconds): a fixed lambda, or --folds/--seed refused with ls
                argv += (["--method", "ls"] if {"--folds", "--seed"} & set(options)
                         else ["--lambda", "1"])
        elif command == "simulate":
            argv = ["simulate", "ec66", "--out", str(folder / "s.csv")]
            if "--poses" not in options:
                argv += ["--poses", "5"]
        else:
            argv = ["plan", "ec66", "--out", str(folder / "p.csv")]
            argv += [] if "--random" in options else ["--random", "40"]
            argv += [] if "--poses" in options else ["--poses", "10"]
        if command == "simulate" and "--poses" in options:
            i = options.index("--poses")
            if options[i + 1] not in ("nan", "inf", "-inf", "-1", "0", "abc", "", "0.5", "-0"):
                options[i + 1] = "5"  # valid sizes stay small: the promise is about bad ones
        if command == "plan" and "--random" in options:
            i = options.index("--random")
            if options[i + 1] in ("1e308", "99999999999999999999", "2"):
                options[i + 1] = "40"
        _promise(argv + options, folder, capsys)
