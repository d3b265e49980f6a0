"""The flush kind: analytic Jacobian on chains with prismatic joints and near flush, the
closed-form start, bad input, and calibration end to end (planted errors recovered from
noise-free touches on a tilted table, held-out errors down to the noise)."""

from dataclasses import replace

import numpy as np
import pytest
from chains import random_chain
from conftest import random_joint_values

import kincal
from kincal import models
from kincal.errors import DataError, IdentifiabilityError, KincalError
from kincal.identification.problem import CalibrationProblem
from kincal.identification.options import CalibrationOptions
from kincal.measurements.flush import FlushData, FlushKind
from kincal.measurements.plane import normal
from kincal.measurements.sets import read_set_file, to_csv_text
from kincal.planning.kind_simulation import flush_offsets, simulate_flush
from kincal.robot import Robot

CONTACT = np.array([0.01, -0.02, 0.1, 0.03, -0.02])  # x, y, z [m], rx, ry [rad], tip frame
TABLE = np.array([[0.1, -0.15, 0.25]])                 # rx, ry [rad], d [m]: a tilted table


def central_differences_check(km, kin, frames, b, tol=1e-6):
    k, f = km.error_model.size, km.n_frames
    x = np.concatenate([kin, frames, b])

    def res(x):
        return km.residuals(x[:k], x[k:k + f], x[k + f:])

    r, Jk, Jf, Jb = km.residuals(kin, frames, b, jacobian=True)
    assert np.allclose(r, res(x))
    J = np.concatenate([Jk, Jf, Jb], axis=2)
    h = 1e-6
    for c in range(x.size):
        e = np.zeros_like(x)
        e[c] = h
        fd = (res(x + e) - res(x - e)) / (2 * h)
        scale = max(np.abs(fd).max(), 1e-3)
        assert np.abs(J[:, :, c] - fd).max() / scale < tol, c


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("model_name", models.MODELS)
def test_jacobian_on_chains_with_prismatic_joints(seed, model_name, tmp_path):
    rng = np.random.default_rng(seed)
    text, cases = random_chain(rng, n=5, cases=("prismatic", "general", "parallel", "gimbal"))
    path = tmp_path / "chain.urdf"
    path.write_text(text)
    robot = Robot.load(path, tip="tip")
    model = models.build(model_name, robot.geometry)
    q = random_joint_values(robot.geometry, rng, 10)
    q[0] = 0.0
    data = FlushData(joint_names=robot.joint_names, joint_values=q, planes=np.arange(10) % 2,
                     labels=("3", "7"), sigma=rng.uniform(0.02, 0.2, 10) * 1e-3)
    km = FlushKind(model, data, backlash=tuple(range(robot.geometry.n)))
    kin = model.nominal + rng.normal(size=model.size) * 1e-2
    central_differences_check(km, kin, rng.normal(size=km.n_frames) * 0.3,
                              rng.normal(size=robot.geometry.n) * 1e-2)


def test_jacobian_near_flush_on_ec66(rng):
    """Where the kind works: touches flush with a tilted table, the contact normal near the
    plane's (tilts near zero)."""
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    data = simulate_flush(em, em.nominal, CONTACT, TABLE, random_joint_values(
        robot.geometry, rng, 1500), 12, 1e-4, 0.1, rng)
    km = FlushKind(em, data, backlash=(0, 5))
    frames = np.r_[TABLE[0], CONTACT[3:], CONTACT[[2, 0, 1]]]  # the point stored z, x, y
    assert np.abs(km.residuals(em.nominal, frames, np.zeros(2))[:, 0]).max() < 1e-3
    central_differences_check(km, em.nominal + rng.normal(size=em.size) * 1e-4, frames,
                              np.array([1e-3, -2e-3]))


@pytest.mark.parametrize("face", [(0.0, 0.0), (np.pi, 0.0), (0.5, -0.4), (-0.3, 1.2)])
def test_start_is_exact_on_noise_free_touches_whatever_the_face(face, rng):
    """A face on the tip's +z or -z side or tilted far from it: the closed-form start
    reproduces noise-free touches (the plane's sign is chosen on the face's side)."""
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    contact = np.r_[0.02, 0.01, 0.08, face]
    data = simulate_flush(em, em.nominal, contact, TABLE, random_joint_values(
        robot.geometry, rng, 3000), 15, 0.0, 0.0, rng)
    km = FlushKind(em, data)
    x0 = km.start(em.nominal, contact[:3])
    assert np.allclose(x0[-3:], contact[[2, 0, 1]])  # the contact point stays at the guess
    assert np.abs(km.residuals(em.nominal, x0, np.zeros(0))).max() < 1e-10
    rx, ry = x0[3:5]
    u = normal(rx, ry)
    assert u[2] >= 0 and np.isclose(abs(u @ normal(*face)), 1.0)


def _write(tmp_path, name, header, rows):
    p = tmp_path / name
    lines = [",".join(header)] + [",".join(repr(float(v)) for v in r) for r in rows]
    p.write_text("\n".join(lines) + "\n")
    return p


def _touches(rng, n=6):
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    data = simulate_flush(em, em.nominal, CONTACT, TABLE, random_joint_values(
        robot.geometry, rng, 1500), n, 0.0, 0.0, rng)
    return robot, em, data


def test_reads_and_writes_flush_files(tmp_path, rng):
    robot, em, data = _touches(rng)
    j = list(robot.joint_names)
    q = data.joint_values
    p = _write(tmp_path, "flush.csv", j + ["plane", "sigma", "sigma_deg"],
               [list(r) + [7.0 if k < 3 else 2.0, 0.05, 0.1] for k, r in enumerate(q)])
    got = read_set_file(p, j, on_plane=True, flush=True, length_unit="mm")
    assert got.kind == "flush" and got.labels == ("2", "7")
    assert np.allclose(got.sigma, 0.05e-3) and np.allclose(got.sigma_deg, 0.1)
    assert np.allclose(got.ratio(), 0.05e-3 / np.radians(0.1))
    km = FlushKind(em, got)
    assert km.frame_names == ("plane2.rx", "plane2.ry", "plane2.d", "plane7.rx", "plane7.ry",
                              "plane7.d", "tool.rx", "tool.ry", "tool.z", "tool.x", "tool.y")
    again = tmp_path / "again.csv"
    again.write_text(to_csv_text(got))
    back = read_set_file(again, j, on_plane=True, flush=True)
    assert np.array_equal(back.joint_values, got.joint_values)
    assert back.labels == got.labels and np.array_equal(back.planes, got.planes)
    assert np.allclose(back.sigma, got.sigma) and np.allclose(back.sigma_deg, got.sigma_deg)
    # without --flush the same file is a plane-contact file
    assert read_set_file(p, j, on_plane=True).kind == "plane"


@pytest.mark.parametrize("columns,values,message", [
    (["plane"], lambda k: [1.0 if k < 4 else 2.0], "2 flush touch\\(es\\) on plane 2; at least 3"),
    (["sigma_deg"], lambda k: [0.1], "column 'sigma_deg' without a 'sigma' column"),
    (["sigma"], lambda k: [0.05 if k else 0.0], "line 2, column 'sigma': 0 is outside the accepted range"),
    (["sigma", "sigma_deg"], lambda k: [0.05, -1.0 if k == 3 else 0.1],
     "line 5, column 'sigma_deg': -1 is outside the accepted range"),
    (["sigma"], lambda k: [float("nan") if k == 2 else 0.05], "line 4"),
    (["plane"], lambda k: [1.5], "a plane is named by a whole number"),
])
def test_bad_flush_files_refused_in_one_line(columns, values, message, tmp_path, rng):
    robot, _, data = _touches(rng)
    j = list(robot.joint_names)
    p = _write(tmp_path, "bad.csv", j + columns,
               [list(r) + values(k) for k, r in enumerate(data.joint_values)])
    with pytest.raises(DataError, match=message) as e:
        read_set_file(p, j, on_plane=True, flush=True)
    assert "\n" not in str(e.value)


def test_too_few_touches_and_touches_on_a_line_refused(tmp_path, rng):
    robot, em, data = _touches(rng)
    j = list(robot.joint_names)
    p = _write(tmp_path, "two.csv", j, data.joint_values[:2].tolist())
    with pytest.raises(DataError, match="2 flush touch\\(es\\) on the plane; at least 3 per "
                                        "plane, not on one line, are needed"):
        read_set_file(p, j, on_plane=True, flush=True)
    # touches that differ only in the last joint: one point, the plane's tilt unfixed
    q = np.repeat(data.joint_values[:1], 6, axis=0)
    q[:, -1] = np.linspace(-1, 1, 6)
    same = FlushData(joint_names=robot.joint_names, joint_values=q)
    with pytest.raises(IdentifiabilityError, match="cannot fix the plane: they spread 0.000 mm"):
        kincal.calibrate(robot, [same], method="ls")


def test_bad_sigmas_in_memory_refused(rng):
    robot, _, data = _touches(rng)
    with pytest.raises(DataError, match="sigma_deg.* needs a height sigma"):
        replace(data, sigma_deg=np.full(len(data), 0.1))
    with pytest.raises(DataError, match="sigma_deg must be 6 positive finite"):
        replace(data, sigma=np.full(6, 1e-4), sigma_deg=np.r_[np.full(5, 0.1), np.inf])
    with pytest.raises(DataError, match="line 7: sigma nan mm is outside the accepted range"):
        replace(data, sigma=np.r_[np.full(5, 1e-4), np.nan])
    with pytest.raises(DataError, match="tilt sigma of flush touches must be a finite value"):
        replace(data, orientation_sigma_deg=0.0)
    with pytest.raises(KincalError, match="plane indices must be 6 values in 0..0"):
        replace(data, planes=np.r_[np.zeros(5, int), 1])


@pytest.mark.parametrize("robot_name,tip", [("ec66", "flange"), ("ur10", "tool0")])
def test_planted_errors_recovered_on_a_tilted_table(robot_name, tip, rng):
    robot = Robot.load(robot_name, tip=tip)
    em = models.build("complete", robot.geometry)
    cand = random_joint_values(robot.geometry, rng, 3000)
    options = CalibrationOptions(method="ls", tool_guess=tuple(CONTACT[:3]))
    ident = CalibrationProblem(robot, [simulate_flush(em, em.nominal, CONTACT, TABLE, cand, 40,
                                                   0.0, 0.0, rng)], options).analyze()
    # what the touches cannot see: the contact point (its offset is the plane's offset's)
    assert {"tool.x", "tool.y", "tool.z"} <= set(ident.dropped)
    assert {"plane1.rx", "plane1.ry", "plane1.d", "tool.rx", "tool.ry"} <= set(ident.kept)
    assert any("held at their start: tool.z .x .y" in n for n in ident.notes)
    kept = [em.names.index(n) for n in ident.kept if n in em.names]
    assert len(kept) >= 15  # a flush touch sees three times what a plane contact sees
    truth = em.nominal.copy()
    truth[kept] += rng.normal(size=len(kept)) * np.where(em.is_length, 0.3e-3,
                                                         np.radians(0.03))[kept]
    data = simulate_flush(em, truth, CONTACT, TABLE, cand, 40, 0.0, 0.0, rng)
    dropped = tuple(n for n in ident.dropped if n in em.names)
    result = kincal.calibrate(robot, [data], options, fix=dropped)
    assert result.converged
    assert np.abs(result.kinematic[kept] - truth[kept]).max() < 1e-9
    frames = dict(zip(result.sets[0].frame_names, result.sets[0].frames))
    assert np.allclose([frames["plane1.rx"], frames["plane1.ry"]], TABLE[0, :2], atol=1e-9)
    assert np.allclose([frames["tool.rx"], frames["tool.ry"]], CONTACT[3:], atol=1e-9)
    # the plane's offset and the contact point's offset along the face normal trade
    # against each other only: the point's height comes out right
    u = normal(frames["tool.rx"], frames["tool.ry"])
    t = np.array([frames["tool.x"], frames["tool.y"], frames["tool.z"]])
    assert abs((frames["plane1.d"] - u @ t) - (TABLE[0, 2] - u @ CONTACT[:3])) < 1e-9


def test_held_out_height_and_tilts_drop_to_the_noise(rng):
    """A tilted table and a second plane at a large angle to it, l2 with a small fixed
    penalty. Flush touches hold the tool's orientation, and the plain least-squares fit is
    ill-conditioned (condition number 3e4-8e4 on EC66): on some seeds it creeps to robots
    with link lengths 0.1-0.4 m off that fit the noisy touches better than the true one
    (held-out heights far below the noise: the simulated noise is made by joint steps
    those robots do not see)."""
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    cand = random_joint_values(robot.geometry, rng, 4000)
    planes = np.array([TABLE[0], [1.3, 0.2, 0.3]])
    truth = em.nominal + np.where(em.is_length, 0.5e-3, np.radians(0.05)) * rng.normal(
        size=em.size)
    noise, noise_deg = 0.02e-3, 0.01

    def touches(candidates, per_plane):
        d = simulate_flush(em, truth, CONTACT, planes, candidates, per_plane, noise,
                           noise_deg, rng)
        return replace(d, sigma=np.full(len(d), noise), sigma_deg=np.full(len(d), noise_deg))

    train, held = touches(cand[:3000], 40), touches(cand[3000:], 15)
    result = kincal.calibrate(robot, [train], method="l2", lam=1e-3,
                              tool_guess=tuple(CONTACT[:3]))
    assert result.converged
    km = FlushKind(em, held)

    def rms(kin, frames):
        r = km.residuals(kin, frames, np.zeros(0))
        return (np.sqrt(np.mean(km.sample_errors(r) ** 2)),
                np.degrees(np.sqrt(np.mean(km.tilt_errors(r) ** 2))))

    h0, a0 = rms(em.nominal, result.x_start[em.size:])
    h1, a1 = rms(result.kinematic, result.sets[0].frames)
    h, a = rms(truth, np.r_[planes.ravel(), CONTACT[3:], CONTACT[[2, 0, 1]]])  # the noise
    assert h0 > 10 * h and a0 > 5 * a  # the planted errors show before
    assert h1 < 1.5 * h and a1 < 1.5 * a  # and after, only the noise is left


def test_poses_selected_for_flush_touches(rng):
    """D-optimal selection among flush touches on two planes beats random subsets."""
    from kincal.planning.pose_selection import select_poses

    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    planes = np.array([TABLE[0], [1.3, 0.2, 0.3]])
    touches = simulate_flush(em, em.nominal, CONTACT, planes, random_joint_values(
        robot.geometry, rng, 3000), 40, 0.0, 0.0, rng)
    sel = select_poses(robot, touches.joint_values, 20, tool=CONTACT[:3], kind="flush",
                       planes=touches.planes, random_subsets=5)
    assert sel.log_det > sel.random_log_det
    assert {"plane2.d", "tool.rx", "tool.ry"} <= set(sel.parameters)
    assert not {"tool.x", "tool.y", "tool.z"} & set(sel.parameters)


def _noisy_touches(rng, noise, noise_deg, per_plane=40):
    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    cand = random_joint_values(robot.geometry, rng, 3000)
    truth = em.nominal + np.where(em.is_length, 0.5e-3, np.radians(0.05)) * rng.normal(
        size=em.size)
    planes = np.array([TABLE[0], [1.3, 0.2, 0.3]])
    g = robot.geometry
    return robot, simulate_flush(em, truth, CONTACT, planes, cand, per_plane, noise,
                                 noise_deg, rng, source="touches.csv", limits=(g.lower, g.upper))


def test_evidence_estimates_the_noise_of_heights_and_tilts_on_their_own(rng):
    """Heights with 0.2 mm and tilts with 0.02 deg of noise (10 mm per deg, the default
    weighs 1 mm against 1 deg): the evidence's variance components find each within 25 %,
    report them labelled in their units, and weigh the rows by them; stated sigmas stay as
    given (one group, the rows' weights as stated)."""
    robot, train = _noisy_touches(rng, 0.2e-3, 0.02)
    result = kincal.calibrate(robot, [train], method="l2", lam="evidence",
                              tool_guess=tuple(CONTACT[:3]))
    groups = {rows: (s, unit) for rows, s, unit in result.evidence.noise_groups}
    assert set(groups) == {"touches.csv height", "touches.csv tilt"}
    assert groups["touches.csv height"][1] == "mm" and groups["touches.csv tilt"][1] == "deg"
    assert groups["touches.csv height"][0] == pytest.approx(0.2, rel=0.25)
    assert groups["touches.csv tilt"][0] == pytest.approx(0.02, rel=0.25)
    assert "touches.csv tilt" in result.evidence.line()
    assert result.evidence.as_dict()["noise_groups"][1]["unit"] == "deg"
    for stated in (dict(orientation_sigma_deg=0.05),
                   dict(sigma=np.full(len(train), 0.05e-3))):
        problem = CalibrationProblem(robot, [replace(train, **stated)], CalibrationOptions(
            method="l2", lam="evidence", tool_guess=tuple(CONTACT[:3])))
        ev = problem.solve().evidence
        assert [g[0] for g in ev.noise_groups] == ["stated sigmas"]
        assert problem.row_scale is None  # the rows weigh as stated


def test_a_kind_of_row_the_parameters_fit_exactly_shares_its_sets_noise(rng):
    """8 touches per plane: 16 heights against more parameters than that, which the fit
    could match exactly (the evidence would then drive their noise to 0): the heights'
    noise is not identified on its own, and the set's rows keep one noise as the kind
    weighs them; with 40 per plane each kind has its own (the test above)."""
    robot, train = _noisy_touches(rng, 0.2e-3, 0.02, per_plane=8)
    problem = CalibrationProblem(robot, [train], CalibrationOptions(
        method="l2", lam="evidence", tool_guess=tuple(CONTACT[:3])))
    result = problem.solve()
    assert [g[0] for g in result.evidence.noise_groups] == ["touches.csv"]
    assert result.sets[0].after.rms > 1e-3  # [mm]: the heights are not fitted exactly
    assert problem.row_scale is None


def test_json_summary_gives_the_noise_of_heights_and_tilts(tmp_path, capsys):
    """The command line: heights with 0.3 mm and tilts with 0.03 deg of noise; --json's
    evidence.noise_groups has each, labelled with the file and its unit; its sets hold the
    tilt errors the human summary prints."""
    from kincal.cli.main import main

    data = tmp_path / "t.csv"
    assert main(["simulate", "ec66", "--kind", "flush", "--poses", "80", "--seed", "1",
                 "--noise-mm", "0.3", "--orientation-noise-deg", "0.03", "--out", str(data),
                 "-q"]) == 0
    capsys.readouterr()
    assert main(["calibrate", "ec66", str(data), "--on-plane", "--flush", "--tool-offset", "0",
                 "0", "0.1", "--out", str(tmp_path / "c.urdf"), "--frames-out",
                 str(tmp_path / "f.json"), "--json"]) == 0
    import json

    out = json.loads(capsys.readouterr().out)
    groups = out["evidence"]["noise_groups"]
    # the tilts the summary prints (they were missing: the top-level errors are heights)
    tilts = out["sets"][0]["orientation_errors"]
    assert tilts["after"]["rms_deg"] < tilts["before"]["rms_deg"] and "residuals" not in out["sets"][0]
    assert [(g["rows"], g["unit"]) for g in groups] == [("t.csv height", "mm"),
                                                        ("t.csv tilt", "deg")]
    assert groups[0]["sigma"] == pytest.approx(0.3, rel=0.3)
    assert groups[1]["sigma"] == pytest.approx(0.03, rel=0.3)


def test_residual_figures_name_the_height(rng, monkeypatch):
    """--plots' residuals.png of flush touches said 'position error (mm)' (the HTML's
    figure said 'height error (mm)'): both take the label from the set's kind."""
    from kincal.export import plots

    robot = Robot.load("ec66", tip="flange")
    em = models.build("complete", robot.geometry)
    data = simulate_flush(em, em.nominal, CONTACT, TABLE,
                          random_joint_values(robot.geometry, rng, 500), 30, 1e-5, 0.01, rng)
    result = kincal.calibrate(robot, [data], method="l2", lam=1e-3,
                              tool_guess=tuple(CONTACT[:3]))
    labels = []
    save = plots._save
    monkeypatch.setattr(plots, "_save", lambda fig, *a, **k: (
        labels.append(fig.axes[0].get_ylabel()), save(fig, *a, **k))[1])
    names = [name for name, _ in plots.calibration_figures(result)]
    assert labels[names.index("residuals.png")] == "height error (mm)"


def test_a_tool_offset_in_millimetres_is_named(tmp_path, capsys):
    """--tool-offset 0 0 -120 (mm) on metre data: contacts have no positions to tell the
    unit by, and the gate refused the 120 m lever arm's motion naming a weak penalty as the
    likely cause. A tool point beyond 3 chain lengths from the tip is now warned about."""
    from kincal.cli.main import main

    data = tmp_path / "t.csv"
    assert main(["simulate", "ec66", "--kind", "flush", "--poses", "30", "--seed", "1",
                 "--out", str(data), "-q"]) == 0
    for offset, warned in (("0.1", False), ("100", True)):
        capsys.readouterr()
        main(["calibrate", "ec66", str(data), "--on-plane", "--flush", "--tool-offset", "0",
              "0", offset, "--out", str(tmp_path / f"c{offset}.urdf"), "-q"])
        err = capsys.readouterr().err
        assert ("lies 100 m from the tip frame, 86 times the chain's length (1.17 m): were its "
                "values millimetres?" in err) == warned, err
