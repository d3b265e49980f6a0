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


def test_the_f_tail_matches_scipy():
    from scipy import stats

    from kincal.identification.diagnosis import f_sf

    for d1 in (1, 2, 3, 7):
        for d2 in (1, 5, 40, 150, 2000):
            for F in (1e-6, 0.05, 0.7, 1.0, 2.5, 9.0, 60.0, 400.0, 1e4):
                want = float(stats.f.sf(F, d1, d2))
                got = f_sf(F, d1, d2)
                assert got == pytest.approx(want, rel=1e-9, abs=1e-300), (F, d1, d2)
    assert f_sf(0.0, 2, 10) == 1.0 and f_sf(float("inf"), 2, 10) == 0.0


def test_a_summary_does_not_import_scipy_stats(tmp_path):
    """The summary's diagnosis runs on every calibration's summary; scipy.stats' import
    alone costs more than the rest of a small command."""
    import subprocess

    robot, data, _ = model_auto.case("EC66", 0, planted=False, term="compliance")
    csv = tmp_path / "poses.csv"
    csv.write_text(data.to_csv_text())
    code = ("import sys\nfrom kincal.cli import main\n"
            f"rc = main(['calibrate', 'ec66', {str(csv)!r}, '--tip', 'flange', '--method', 'ls', "
            f"'--tool-offset', '0.03', '-0.02', '0.1', '--out', {str(tmp_path / 'o.urdf')!r}])\n"
            "print('STATS:', 'scipy.stats' in sys.modules, rc)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True)
    assert "diagnosis" in out.stdout or "kincal calibration" in out.stdout, out
    assert out.stdout.strip().splitlines()[-1] == "STATS: False 0", out.stdout[-2000:]


def test_a_large_set_is_diagnosed_on_evenly_spaced_poses(monkeypatch):
    """Beyond MAX_POSES the test looks at that many poses spread over the file (their
    approach directions from the whole sequence): the planted term is still named."""
    import kincal.identification.diagnosis as diagnosis

    warnings.simplefilter("ignore", KincalWarning)
    robot, data, joint = model_auto.case("EC66", 0, planted=True, term="compliance")
    res = calibrate(robot, data, model="complete")
    whole = diagnose(res)
    monkeypatch.setattr(diagnosis, "MAX_POSES", 40)
    part = diagnose(res)
    assert (part.joint, part.cause) == (whole.joint, whole.cause) == (joint, "compliance")
    assert part.size == pytest.approx(whole.size, rel=0.1) and part.p_value > whole.p_value
