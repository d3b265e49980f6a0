"""The residual diagnosis names a joint compliance (the joint turns with the gravity torque
it carries) with its size, even when the model is given by hand."""

import sys
import warnings
from pathlib import Path

import pytest

from kincal.errors import KincalWarning
from kincal.identification.diagnosis import diagnose
from kincal.identification.problem import calibrate

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))
import model_auto  # noqa: E402  (the study's simulated cases)


@pytest.mark.parametrize("name,seed", [("EC66", 0), ("UR10", 1)])
def test_diagnosis_names_a_planted_compliance_with_its_size(name, seed):
    warnings.simplefilter("ignore", KincalWarning)
    robot, data, joint = model_auto.case(name, seed, planted=True, term="compliance")
    res = calibrate(robot, data, model="complete")
    f = diagnose(res)
    assert (f.joint, f.cause) == (joint, "compliance")
    # the planted deflection at the RMS torque [deg]
    assert f.size == pytest.approx(float(model_auto.np.degrees(model_auto.DEFLECTION)), rel=0.1)
    assert f.line() in res.summary() and f"--compliance {joint}" in f.line()
    assert f.as_dict()["cause"] == "compliance" and f.rms_mm[1] < f.rms_mm[0]
    # once modelled, the pattern is gone from the diagnosis
    assert diagnose(calibrate(robot, data, model="complete", compliance=(joint,))) is None


@pytest.mark.parametrize("name,seed", [("EC66", 0), ("UR10", 2)])
def test_no_compliance_is_named_on_clean_data(name, seed):
    warnings.simplefilter("ignore", KincalWarning)
    robot, data, _ = model_auto.case(name, seed, planted=False, term="compliance")
    assert diagnose(calibrate(robot, data, model="complete")) is None
