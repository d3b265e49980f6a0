"""kincal plan --model: the poses are chosen for the parameters of the error model that will
be calibrated (the choices and the default of calibrate's --model, one definition). Without
it plan always chose for the chain's default model: re-mastering a robot (--model offsets,
joint zeros only) got poses chosen to see link lengths and twists it would never fit."""

import json

import pytest

from kincal.cli.main import build_parser, main
from kincal.models import MODELS

PLAN = ["plan", "ec66", "--random", "200", "--poses", "30", "--tool-offset", "0", "0", "0.1"]


def _plan(tmp_path, capsys, *extra) -> dict:
    out = tmp_path / f"chosen{len(list(tmp_path.iterdir()))}.csv"
    capsys.readouterr()
    assert main([*PLAN, "--out", str(out), "--json", *extra]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert out.exists()
    return summary


def test_the_plan_is_for_the_model_asked(tmp_path, capsys):
    plans = {m: _plan(tmp_path, capsys, "--model", m) for m in ("offsets", "complete")}
    names = {m: [e["name"] for e in s["std_errors"]] for m, s in plans.items()}
    kinematic = {m: [n for n in v if n.startswith("joint_")] for m, v in names.items()}
    # offsets: the joint zeros alone; complete: lengths and twists as well
    assert kinematic["offsets"] and all(n.endswith(".theta") for n in kinematic["offsets"])
    assert any(n.endswith((".a", ".alpha", ".d")) for n in kinematic["complete"])
    assert [s["model"] for s in plans.values()] == ["offsets", "complete"]
    assert plans["offsets"]["joint_values_si"] != plans["complete"]["joint_values_si"]
    assert plans["offsets"]["log_det"] != plans["complete"]["log_det"]


def test_auto_plans_for_the_chains_default_model(tmp_path, capsys):
    """auto, the default as in calibrate: the model calibrate's auto starts from and keeps
    unless the data tell otherwise, the chain's default."""
    from kincal.models import default_for
    from kincal.robot import Robot

    default = default_for(Robot.load("ec66").geometry)
    given, auto = _plan(tmp_path, capsys, "--model", default), _plan(tmp_path, capsys)
    assert auto["model"] == default
    assert auto["joint_values_si"] == given["joint_values_si"]


def test_the_summary_names_the_model(tmp_path, capsys):
    capsys.readouterr()
    assert main([*PLAN, "--out", str(tmp_path / "c.csv"), "--model", "mdh"]) == 0
    assert "error model mdh" in capsys.readouterr().out


def test_an_unknown_model_is_refused_with_the_choices(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        main([*PLAN, "--out", str(tmp_path / "c.csv"), "--model", "dh"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "--model" in err and all(m in err for m in ("auto", *MODELS)), err
    assert not list(tmp_path.iterdir())


def test_plan_and_calibrate_share_the_model_option():
    """One definition: the same choices and default in both commands."""
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    options = [next(a for a in sub[c]._actions if a.dest == "model") for c in ("plan", "calibrate")]
    assert options[0].choices == options[1].choices and options[0].default == options[1].default
