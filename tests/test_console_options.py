"""-q/-v on every command, calibrate --json, and the progress display's estimate."""

import io
import json

import pytest

from kincal.cli.main import build_parser, main
from kincal.cli.progress import progress_bar, timing


def test_every_command_takes_quiet_and_verbose():
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    for name, p in sub.choices.items():
        flags = {s for a in p._actions for s in a.option_strings}
        assert {"-q", "--quiet", "-v", "--verbose"} <= flags, name


@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    d = tmp_path_factory.mktemp("console")
    assert main(["simulate", "ec66", "--out", str(d / "cal.csv"), "--poses", "30", "--seed", "2",
                 "--tool-m", "0.03", "0.02", "0.12"]) == 0
    return d / "cal.csv"


def test_quiet_prints_nothing_on_stdout(cal, tmp_path, capsys):
    capsys.readouterr()
    assert main(["analyze", "ec66", str(cal), "-q"]) == 0
    assert main(["simulate", "ec66", "--out", str(tmp_path / "s.csv"), "--poses", "5", "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and (tmp_path / "s.csv").exists()
    assert cap.err.strip().splitlines()[-1].startswith("kincal: done in ")  # stderr keeps it


def test_verbose_names_the_command_and_the_error_kind(cal, capsys):
    capsys.readouterr()
    assert main(["evaluate", "ec66", str(cal), "--fit-frames", "--tip", "flang", "-v"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("kincal ") and "evaluate" in err[0]
    assert [line for line in err if line.startswith("kincal: error:")][0].endswith("[FrameError]")
    # an option refused before the work: the version and command line first too (it was
    # said after the options' checks, so not at all then)
    assert main(["demo", "--out", str(cal), "-v"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("kincal ") and "demo" in err[0], err
    assert err[1].startswith("kincal: error:") and err[1].endswith("[OptionError]"), err


def test_json_is_the_only_thing_on_stdout(cal, tmp_path, capsys):
    held = tmp_path / "held.csv"  # other poses of the same robot (a training file is refused)
    assert main(["simulate", "ec66", "--out", str(held), "--poses", "30", "--seed", "3",
                 "--tool-m", "0.03", "0.02", "0.12", "-q"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(cal), "--lambda", "0.01", "--out",
                 str(tmp_path / "c.urdf"), "--validate", str(held), "--json"]) == 0
    cap = capsys.readouterr()
    summary = json.loads(cap.out)  # the whole of stdout is one JSON object
    assert summary["format"] == "kincal-summary-1" and summary["verdict"] == "written"
    assert summary["written"] == [str(tmp_path / "c.urdf")]
    assert summary["errors"]["after"]["mean_mm"] < summary["errors"]["before"]["mean_mm"]
    assert summary["validation"]["samples"] == 30
    assert f"kincal: wrote {tmp_path / 'c.urdf'}" in cap.err


def test_progress_shows_elapsed_time_and_an_estimate():
    assert timing(10.0, 2, 10) == "10.0 s, about 40 s left"
    assert timing(120.0, 1, 2) == "120.0 s, about 2 min left"
    assert timing(3.0, 5, 5) == "3.0 s"  # done: no estimate

    class Tty(io.StringIO):
        def isatty(self):
            return True

    stream = Tty()
    bar = progress_bar(stream)
    bar(1, 4)
    assert "1/4 fits" in stream.getvalue() and "left" in stream.getvalue()


def test_no_negative_zero_in_the_report_figures():
    from kincal.export.html_report import _frame_value, _num
    from kincal.identification.result_text import _z

    assert _num(-3e-9, "+.5f") == "+0.00000" and _num(-3e-9, ".5f") == "0.00000"
    assert _num(-2e-5, "+.5f") == "-0.00002"  # a value the digits show stays signed
    assert _frame_value("base.x", -1e-12) == "0.0000"
    assert f"{_z(-4e-5, 4):.4f}" == "0.0000" and f"{_z(-4e-5):.5f}" == "-0.00004"


def test_a_warning_raised_twice_is_said_once(monkeypatch, capsys):
    """Work that fits the same data twice (a prior, the model choice) may raise one warning
    twice; the console says each line once, in order, and every distinct one."""
    import warnings

    import kincal.cli.checks as checks
    from kincal.errors import KincalWarning, OptionError

    def check_args(args):
        for message in ("the same thing", "another thing", "the same thing"):
            warnings.warn(message, KincalWarning)
        raise OptionError("stop here")

    monkeypatch.setattr(checks, "check_args", check_args)
    assert main(["evaluate", "ec66", "data.csv"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err == ["kincal: error: stop here", "kincal: warning: the same thing",
                   "kincal: warning: another thing"], err


def test_verbose_says_each_note_once(tmp_path, capsys):
    """-v added the identifiability report, whose notes the summary prints under its
    identifiable line already: each note came twice (flush touches: three notes)."""
    data = tmp_path / "flush.csv"
    assert main(["simulate", "ec66", "--kind", "flush", "--poses", "30", "--seed", "1",
                 "--out", str(data), "-q"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data), "--on-plane", "--flush", "--tool-offset", "0",
                 "0", "0.1", "--out", str(tmp_path / "c.urdf"), "-v"]) == 0
    out = capsys.readouterr().out.splitlines()
    notes = [line for line in out if line.strip().startswith("note:")]
    assert notes and len(notes) == len(set(notes)), notes
    assert any(line.strip().startswith("dropped ") for line in out)  # -v's own lines stay
