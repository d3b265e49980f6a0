"""Several chains of one robot in one calibration, sharing the joints they traverse: the
Jacobian of a two-chain problem against central differences, planted errors on shared joints
recovered from two chains, two chains together against each alone on held-out poses, the
corrected URDF (one original tree, every corrected origin) through Pinocchio, FRAMES.json
per set, the command line and its refusals."""

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from chains import random_tree

from kincal.cli.main import main
from kincal.errors import ChainError, OptionError
from kincal.export.outputs import corrected_urdf_text
from kincal.frames_file import CellFrames
from kincal.identification.chains import Chains
from kincal.identification.options import CalibrationOptions
from kincal.identification.problem import CalibrationProblem, calibrate
from kincal.measurements.data import Measurements
from kincal.measurements.flush import FlushData
from kincal.models.chain import Chain
from kincal.robot import Robot
from kincal.rotations import base_rotation

STEP = 1e-6  # central differences in the solver's variables (mm, deg): O(STEP^2) + roundoff
TOOLS = (np.array([0.03, -0.02, 0.05]), np.array([-0.04, 0.01, 0.06]))
FRAMES = (np.array([0.5, -0.2, 0.1, 0.1, -0.2, 0.3]), np.array([-0.3, 0.4, 0.2, -0.1, 0.2, 1.0]))


def _tree(tmp_path, seed=3):
    """A random tree (tests/chains.py) and two chains sharing its trunk ``t``: the root to
    leaf ``atip`` (all forward), and leaf ``ctip`` up its branch, through the root, down the
    trunk and branch b to ``btip``."""
    text, joints = random_tree(np.random.default_rng(seed))
    path = tmp_path / f"tree_{seed}.urdf"
    path.write_text(text)
    return (Robot.load(path, base="base_link", tip="atip"),
            Robot.load(path, base="ctip", tip="btip")), joints


def _q(robot, n, rng):
    g = robot.geometry
    lo = np.where(np.isfinite(g.lower), g.lower, -np.pi)
    hi = np.where(np.isfinite(g.upper), g.upper, np.pi)
    return rng.uniform(0.8 * lo, 0.8 * hi, (n, g.n))


def _points(robot, true, q, k, noise=0.0, rng=None, source=""):
    """Point measurements of chain k's tool point on the true robot (Pinocchio), in a
    measurement frame (FRAMES[k]: the base frame's pose in it)."""
    T = true.tip_poses(q)
    P = T[:, :3, 3] + T[:, :3, :3] @ TOOLS[k]
    b = FRAMES[k]
    M = P @ base_rotation(*b[3:]).T + b[:3]
    if noise:
        M = M + rng.normal(0, noise, M.shape)
    return Measurements(joint_names=robot.joint_names, joint_values=q, positions=M,
                        source=source or f"chain{k + 1}")


def _truth(robots, kin_scale, rng, model="placement", planted=None):
    ch = Chains(list(robots), 2, model)
    kin = rng.normal(0, kin_scale, ch.model.size) if planted is None else planted(ch)
    origins = ch.origins(kin)
    return ch, kin, [r.with_origins(origins) for r in robots]


def _identifiable(robots, qs):
    """The kinematic parameters two point sets at poses ``qs`` identify (nominal data)."""
    sets = [_points(robots[k], robots[k], qs[k], k) for k in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = CalibrationProblem(list(robots), sets, CalibrationOptions(method="ls"))
        kept = set(p.analyze().kept)
    return [k for k, n in enumerate(p.layout.kinematic_names) if n in kept]


def _planted_on_identifiable(robots, qs, scale, rng):
    """Errors planted in the identifiable kinematic parameters only (the others redundant
    over the union or too weak: the data cannot tell what they were)."""
    keep = _identifiable(robots, qs)

    def planted(ch):
        kin = np.zeros(ch.model.size)
        kin[keep] = rng.normal(0, scale, len(keep))
        return kin

    return _truth(robots, 0, rng, planted=planted)


def test_union_layout_one_set_of_parameters_per_shared_joint(tmp_path):
    robots, joints = _tree(tmp_path)
    ch = Chains(list(robots), 2)
    names = ch.model.names
    assert len(names) == len(set(names))
    for j in joints["t"]:  # the trunk is on both chains: its six errors once
        assert [n for n in names if n.startswith(j + ".")] == [f"{j}.{f}" for f in
                                                                ("tx", "ty", "tz", "rx", "ry", "rz")]
    # every traversed origin has its errors, the top reversed joint's (c's first) included
    assert f"{joints['c'][0]}.tx" in ch.models[1].names
    for m, idx in zip(ch.models, ch.idx):
        assert tuple(names[k] for k in idx) == m.names


def test_two_chain_jacobian_against_central_differences(tmp_path):
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(0)
    sets = [_points(robots[k], robots[k], _q(robots[k], 12, rng), k) for k in range(2)]
    # and a flush set on chain 2 (its residuals need no consistent data for a Jacobian)
    sets.append(FlushData(joint_names=robots[1].joint_names, joint_values=_q(robots[1], 8, rng)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = CalibrationProblem([robots[0], robots[1], robots[1]], sets,
                               CalibrationOptions(backlash=("aj1", "tj2", "bj1")))
    assert p.chains.several and p.layout.backlash == ("tj2", "aj1", "bj1")  # union order
    u = p.start() / p.scale + rng.normal(0, 0.5, p.layout.size)  # off the start: mm, deg
    f = p.residual_function()
    _, J = f(u, True)
    D = np.empty_like(J)
    for k in range(len(u)):
        e = np.zeros(len(u))
        e[k] = STEP
        D[:, k] = (f(u + e, False)[0] - f(u - e, False)[0]) / (2 * STEP)
    assert np.abs(J - D).max() < 1e-6 * max(1.0, np.abs(D).max())
    # the columns of a chain's set are zero for parameters of joints off that chain
    only_b = [k for k, n in enumerate(p.layout.kinematic_names) if n.startswith("b")]
    rows = slice(0, 3 * 12)
    assert only_b and np.all(J[rows, only_b] == 0)


@pytest.mark.parametrize("seed", [3, 7])
def test_planted_errors_recovered_from_two_chains(tmp_path, seed):
    """Noise-free points on two chains, errors planted in the parameters they identify
    (placement): recovered to 1e-9, both chains' tool points reproduced at held-out poses,
    and the corrected URDF (the one original tree) reproduces every chain's model to
    1e-12 m through Pinocchio."""
    robots, _ = _tree(tmp_path, seed)
    rng = np.random.default_rng(seed)
    qs = [_q(robots[k], 40, rng) for k in range(2)]
    ch, kin, true = _planted_on_identifiable(robots, qs, 2e-3, rng)
    sets = [_points(robots[k], true[k], qs[k], k) for k in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(list(robots), sets, method="ls")
    assert res.layout.kinematic_names == ch.model.names
    assert np.abs(res.kinematic - kin).max() < 1e-9
    for k in range(2):
        em, idx = res.chains.chain_of(k)
        q = _q(robots[k], 30, rng)
        s = Chain(em, q).state(res.kinematic[idx], None, keep=False)
        T = true[k].tip_poses(q)
        err = (s.p_tip + s.R_tip @ TOOLS[k]) - (T[:, :3, 3] + T[:, :3, :3] @ TOOLS[k])
        assert np.abs(err).max() < 1e-9
    # the corrected URDF: reload each chain from the written text, compare with the model
    path = tmp_path / "corrected.urdf"
    path.write_text(corrected_urdf_text(res))
    for k in range(2):
        em, idx = res.chains.chain_of(k)
        back = Robot.load(path, base=robots[k].base, tip=robots[k].tip)
        q = _q(robots[k], 20, rng)
        s = Chain(em, q).state(res.kinematic[idx], None, keep=False)
        T = back.tip_poses(q)
        assert np.abs(T[:, :3, 3] - s.p_tip).max() < 1e-12
        assert np.abs(T[:, :3, :3] - s.R_tip).max() < 1e-12


def test_planted_offsets_of_shared_joints_recovered(tmp_path):
    """Joint offsets planted on the two trunk joints, which both chains traverse: recovered
    to 1e-9 rad from the two chains together (offsets model)."""
    robots, joints = _tree(tmp_path)
    rng = np.random.default_rng(1)
    trunk = [f"{j}.theta" for j in joints["t"]]

    def planted(ch):
        kin = np.zeros(ch.model.size)
        kin[[ch.model.names.index(n) for n in trunk]] = (0.01, -0.02)
        return kin

    ch, kin, true = _truth(robots, 0, rng, "offsets", planted)
    sets = [_points(robots[k], true[k], _q(robots[k], 30, rng), k) for k in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(list(robots), sets, method="ls", model="offsets")
    for n, v in zip(trunk, (0.01, -0.02)):
        assert res.parameter(n).status == "identified"
        assert abs(res.parameter(n).estimate - v) < 1e-9
    assert np.abs(res.kinematic).max() < 0.021  # nothing else moved much


def test_two_chains_together_at_least_as_good_as_each_alone(tmp_path):
    """Noisy points (20 um), few poses on chain 1: calibrated together, each chain predicts
    its held-out measurements at least as well as calibrated alone (RMS over four noise
    draws: one draw can favour either by a few percent), chain 1 markedly better."""
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(5)
    qs = [_q(robots[k], n, rng) for k, n in ((0, 25), (1, 60))]
    ch, kin, true = _planted_on_identifiable(robots, qs, 1e-3, rng)
    held = [_q(robots[k], 200, rng) for k in range(2)]

    def held_out(res, k, i):
        """RMS [m] of chain k's predicted measurements (its set i's frames) at held-out
        poses against the noise-free truth: what the frames and kinematics give together,
        free of the gauge between the measurement frame and the first joints."""
        em, idx = (res.error_model, slice(None)) if not res.chains.several \
            else res.chains.chain_of(i)
        s = Chain(em, held[k]).state(res.kinematic[idx], None, keep=False)
        f = res.sets[i].frames
        P = (s.p_tip + s.R_tip @ f[6:9]) @ base_rotation(*f[3:6]).T + f[:3]
        d = P - _points(robots[k], true[k], held[k], k).positions
        return float(np.mean(np.sum(d ** 2, axis=1)))

    together, alone = np.zeros(2), np.zeros(2)
    for _ in range(4):
        sets = [_points(robots[k], true[k], qs[k], k, 20e-6, rng) for k in range(2)]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            both = calibrate(list(robots), sets, method="ls")
            for k in range(2):
                together[k] += held_out(both, k, k)
                alone[k] += held_out(calibrate(robots[k], [sets[k]], method="ls",
                                               model="placement"), k, 0)
    together, alone = np.sqrt(together / 4), np.sqrt(alone / 4)
    # chain 1 (few poses) gains from chain 2's view of the shared trunk; chain 2 (many) can
    # only gain little, and four draws resolve its expected gain to about 1 %
    assert together[0] < 0.95 * alone[0] and together[1] <= 1.01 * alone[1], (together, alone)


@pytest.mark.parametrize("method, chains", [
    ("l2", (("base_link", "atip"), ("ctip", "btip"))),
    ("ls", (("base_link", "atip"), ("ctip", "btip"))),
    # the second chain climbs the first's joints: the union lists them in its order
    ("ls", (("base_link", "atip"), ("atip", "ctip"))),
    ("l2", (("atip", "btip"), ("btip", "atip"))),
    ("l2", (("base_link", "atip"), ("ctip", "btip"), ("atip", "ctip")))])
def test_several_chains_calibrate_alike_in_any_order(tmp_path, method, chains):
    """The data files of several chains given in every order: the same parameters kept and
    the same corrected URDF origins. The identifiability analysis takes each chain's own
    joints (the chains by their names) and then the joints on several chains, deepest first
    (Chains.preference). In the union's order (file order) a shared joint carried the
    first-listed chain's share of what it has in common with each chain's own origins, the
    second chain's own origins carried theirs, and the penalty toward nominal weighed the
    two representations differently; with a chain climbing the other's joints, the shared
    joints' own order followed the files too."""
    import itertools

    robots, _ = _tree(tmp_path)
    path = robots[0].source
    robots = [Robot.load(path, base=b, tip=t) for b, t in chains]
    rng = np.random.default_rng(11)
    qs = [_q(r, n, rng) for r, n in zip(robots, (30, 40, 35))]
    ch = Chains(robots, len(robots), "placement")
    origins = ch.origins(rng.normal(0, 1e-3, ch.model.size))
    true = [r.with_origins(origins) for r in robots]
    sets = [_points(robots[k], true[k], qs[k], k % 2, 20e-6, rng) for k in range(len(robots))]
    fits = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for order in itertools.permutations(range(len(robots))):
            options = {"lam": "evidence"} if method == "l2" else {}
            res = calibrate([robots[k] for k in order], [sets[k] for k in order],
                            method=method, **options)
            kept = {n for n in res.identifiability.kept
                    if n.split(".")[0] in res.chains.model.joint_names}
            fits.append((kept, res.chains.origins(res.kinematic)))
    (kept0, o0), rest = fits[0], fits[1:]
    assert kept0
    for kept, o in rest:
        assert kept == kept0, sorted(kept ^ kept0)
        assert set(o) == set(o0)
        worst = max(float(np.abs(o0[j] - o[j]).max()) for j in o0)
        assert worst < 1e-9, worst


def test_a_shared_plane_keeps_the_same_parameters_in_either_order(tmp_path):
    """Two arms from one base touching one plane (--shared-plane): the shared plane links
    the two chains' own joints, and which of them the analysis kept followed the order of
    the files (aj1.ty in one, bj1.ty in the other, on seeds 3 and 5 of the random tree)."""
    from scipy.optimize import least_squares

    from kincal.measurements.plane import PlaneData

    tool = np.array([0.02, -0.01, 0.05])
    for seed in (3, 5):
        robots, _ = _tree(tmp_path, seed)
        path = robots[0].source
        robots = [Robot.load(path, base="base_link", tip=t) for t in ("atip", "btip")]
        rng = np.random.default_rng(seed)
        n = np.array([0.0, 0.3, 1.0]) / np.linalg.norm([0.0, 0.3, 1.0])

        def height(r, q):
            T = r.tip_poses(np.atleast_2d(q))
            return (T[:, :3, 3] + T[:, :3, :3] @ tool) @ n

        c = np.median(np.concatenate([height(r, _q(r, 50, rng)) for r in robots]))
        sets = []
        for k, r in enumerate(robots):  # touches of the plane height = c, near random poses
            qs = [least_squares(lambda q: np.r_[height(r, q) - c, 1e-4 * (q - q0)], q0).x
                  for q0 in _q(r, 60, rng)]
            qs = [q for q in qs if abs(height(r, q)[0] - c) < 1e-6][:40]
            sets.append(PlaneData(joint_names=r.joint_names, joint_values=np.array(qs),
                                  source=f"p{k}"))
        kept = []
        for order in ((0, 1), (1, 0)):
            p = CalibrationProblem([robots[k] for k in order], [sets[k] for k in order],
                                   CalibrationOptions(method="ls", shared_planes=True,
                                                      tool_guess=tuple(tool)))
            kept.append({m for m in p.analyze().kept
                         if m.split(".")[0] in p.chains.model.joint_names})
        assert kept[0] and kept[0] == kept[1], (seed, sorted(kept[0] ^ kept[1]))


def test_bad_input_refused(tmp_path):
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(0)
    sets = [_points(robots[k], robots[k], _q(robots[k], 12, rng), k) for k in range(2)]
    for model in ("complete", "mdh"):
        with pytest.raises(OptionError, match=f"error model {model} cannot calibrate several "
                                              "chains.*placement, offsets"):
            CalibrationProblem(list(robots), sets, CalibrationOptions(model=model))
    other = tmp_path / "other.urdf"
    other.write_text(random_tree(np.random.default_rng(99))[0])
    stranger = Robot.load(other, base="ctip", tip="btip")
    with pytest.raises(OptionError, match="must come from one URDF"):
        CalibrationProblem([robots[0], stranger], sets)
    with pytest.raises(OptionError, match="3 robots for 2 measurement sets"):
        CalibrationProblem([robots[0]] * 3, sets)
    # a chain ending on its way up cannot carry the origin another chain corrects
    climbing = Robot.load(robots[0].source, base="atip", tip="base_link")
    with pytest.raises(ChainError, match="ends climbing through tj1, whose origin .in "
                                         "base_link.*a movable joint down from base_link"):
        Chains([robots[0], climbing], 2)


def test_climbing_refusal_advice_is_followable(tmp_path):
    """The refusal of a chain that ends climbing names a way out that works: a tip reached
    through a movable joint down from the lost origin's link (there base_link, the root:
    "a tip below its parent link" said before would name every link, the refused one too)."""
    robots, _ = _tree(tmp_path)
    with pytest.raises(ChainError, match="down from base_link"):
        Chains([robots[0], Robot.load(robots[0].source, base="atip", tip="base_link")], 2)
    down = Robot.load(robots[0].source, base="atip", tip="ctip")  # base_link down branch c
    assert Chains([robots[0], down], 2).several


def test_frames_file_records_each_sets_chain(tmp_path):
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(2)
    ch, kin, true = _truth(robots, 1e-3, rng)
    sets = [_points(robots[k], true[k], _q(robots[k], 30, rng), k) for k in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(list(robots), sets, method="ls")
    from kincal.errors import ExportError
    from kincal.export.outputs import Outputs, write_calibration

    for one_chain in (Outputs(mdh=tmp_path / "MDH.csv"),
                      Outputs(yaml=tmp_path / "K.yaml", yaml_format="ur", ur_hash="calib_1")):
        with pytest.raises(ExportError, match="describe one chain; this calibration has several"):
            write_calibration(res, one_chain)
    assert not list(tmp_path.glob("MDH.csv")) + list(tmp_path.glob("K.yaml"))
    text = res.frames().dumps()
    back = CellFrames.from_dict(json.loads(text))
    assert [(s.base_frame, s.tip_frame) for s in back.sets] == [("base_link", "atip"),
                                                                ("ctip", "btip")]
    # the file says it holds two chains (its top-level chain keys, version 1's tool and
    # frames among them, are the first's: a reader of those alone read the second chain's
    # data with the first's frames); one chain's file has no such list
    assert json.loads(text)["chains"] == [{"base_frame": "base_link", "tip_frame": "atip"},
                                          {"base_frame": "ctip", "tip_frame": "btip"}]
    assert "chains" not in json.loads(back.for_chain("ctip", "btip").dumps())
    # an older file without them: the sets are on the top-level chain
    data = json.loads(text)
    for s in data["sets"]:
        del s["base_frame"], s["tip_frame"]
    old = CellFrames.from_dict(data)
    assert {(s.base_frame, s.tip_frame) for s in old.sets} == {("base_link", "atip")}


def _csv(path, data):
    path.write_text(data.to_csv_text())
    return str(path)


def test_command_line_two_chains_and_count_refusals(tmp_path, capsys):
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(4)
    ch, kin, true = _truth(robots, 1e-3, rng)
    files = [_csv(tmp_path / f"s{k}.csv", _points(robots[k], true[k], _q(robots[k], 40, rng),
                                                  k, 10e-6, rng)) for k in range(2)]
    urdf = str(robots[0].source)
    out, frames = tmp_path / "CAL.urdf", tmp_path / "FRAMES.json"
    before = {p: p.read_bytes() for p in tmp_path.iterdir()}
    for base, tip, what in ((["base_link", "ctip", "ctip"], ["atip", "btip"], "--base"),
                            (["base_link", "ctip"], ["atip", "btip", "btip"], "--tip")):
        assert main(["calibrate", urdf, *files, "--base", *base, "--tip", *tip,
                     "--out", str(out), "--quiet"]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"kincal: error: {what} takes one frame")
        assert "2 data files, 3 " in err[0]
    assert main(["calibrate", urdf, *files, "--shared-plane", "--out", str(out)]) == 1
    assert "--shared-plane shares the planes of plane contacts" in capsys.readouterr().err
    assert main(["calibrate", urdf, *files, "--base", "base_link", "ctip", "--tip", "atip",
                 "btip", "--accuracy-map", "0", "0", "0", "0.1", "--out", str(out)]) == 1
    assert "describe one chain; this calibration has several" in capsys.readouterr().err
    for one_chain in (["--mdh-out", str(tmp_path / "MDH.csv")],
                      ["--yaml-out", str(tmp_path / "K.yaml"), "--yaml-format", "ur",
                       "--ur-hash", "calib_1"]):
        assert main(["calibrate", urdf, *files, "--base", "base_link", "ctip", "--tip", "atip",
                     "btip", *one_chain, "--out", str(out)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "describe one chain; this calibration has several" in err[0]
    # --validate: one held-out file per data file with several chains, refused before any
    # fit otherwise
    other = tmp_path / "held.csv"  # not a data file (a data file as --validate is refused)
    other.write_text("# held out\n" + Path(files[1]).read_text())
    for held, said in (([str(other)], "give one held-out file per data file (here 2)"),
                       ([str(other)] * 3, "2 data file(s), 3 --validate files")):
        assert main(["calibrate", urdf, *files, "--base", "base_link", "ctip", "--tip", "atip",
                     "btip", "--validate", *held, "--out", str(out)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0], err
    other.unlink()
    assert {p: p.read_bytes() for p in tmp_path.iterdir()} == before  # nothing written
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["calibrate", urdf, *files, "--base", "base_link", "ctip", "--tip", "atip",
                     "btip", "--method", "ls", "--out", str(out), "--frames-out", str(frames),
                     "--yaml-out", str(tmp_path / "K.yaml"), "--quiet"]) == 0
    # the YAML lists every chain's joints, each origin as the corrected URDF has it
    from kincal.export.cell_exports import read_kinematics_yaml

    origins = read_kinematics_yaml((tmp_path / "K.yaml").read_text())
    union = tuple(dict.fromkeys(j for r in robots for j in r.joint_names))
    assert tuple(origins) == union
    written = Robot.load(out, base="base_link", tip="atip").urdf_origins(union)
    for j in union:
        assert np.abs(origins[j] - written[j]).max() < 1e-12, j
    f = CellFrames.read(frames)
    assert [(s.base_frame, s.tip_frame) for s in f.sets] == [("base_link", "atip"),
                                                             ("ctip", "btip")]
    for k in range(2):  # the one corrected URDF holds both chains' corrections
        q = _q(robots[k], 50, rng)
        truth = _points(robots[k], true[k], q, k).positions
        s = f.sets[k]
        errors = []
        for robot in (robots[k], Robot.load(out, base=robots[k].base, tip=robots[k].tip)):
            T = robot.tip_poses(q)
            P = (T[:, :3, 3] + T[:, :3, :3] @ s.tools[0]) @ base_rotation(*s.base[3:]).T
            errors.append(np.abs(P + s.base[:3] - truth).max())
        assert errors[1] < 0.1e-3 and errors[1] < 0.1 * errors[0], errors
    # kincal evaluate on one chain: without --base/--tip refused, naming the chains (the
    # first chain's frames judged the other chain's data with a warning only, then without a
    # word); each chain by its base and tip
    capsys.readouterr()
    for data in files:
        assert main(["evaluate", str(out), data, "--frames", str(frames)]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err == ["kincal: error: " + str(frames) + " holds the frames of 2 chains "
                       "(base_link -> atip, ctip -> btip): give --base and --tip of the chain "
                       "meant (the data or targets of another chain are metres off with these "
                       "frames)"], err
    assert main(["evaluate", str(out), files[0], "--base", "base_link", "--tip", "atip",
                 "--frames", str(frames)]) == 0
    said = capsys.readouterr().out
    assert main(["evaluate", str(out), files[1], "--base", "ctip", "--tip", "btip",
                 "--frames", str(frames)]) == 0
    said += capsys.readouterr().out
    assert "(base_link -> atip)" in said and "(ctip -> btip)" in said
    rms = [float(line.split("RMS")[1].split()[0]) for line in said.splitlines() if "RMS" in line]
    assert len(rms) == 2 and max(rms) < 0.05, said  # [mm]: noise 0.01 mm per axis
    # one of the two frames given: the recorded chain that has it (--tip btip alone was
    # refused, 'use --tip atip', the first chain's); a chain the file lacks: the error lists
    # the chains it holds
    assert main(["evaluate", str(out), files[1], "--tip", "btip", "--frames", str(frames)]) == 0
    assert f"{rms[1]:.3f}" in capsys.readouterr().out.split("(ctip -> btip)")[1]
    assert main(["evaluate", str(out), files[1], "--base", "base_link", "--tip", "btip",
                 "--frames", str(frames)]) == 1
    assert ("identified for base_link -> atip, ctip -> btip); give --base and --tip of one of "
            "them") in capsys.readouterr().err
    # calibrate --validate with one held-out file per data file: each judged on its file's
    # chain with its set's frames, as kincal evaluate judges it from the files written
    held = [_csv(tmp_path / f"h{k}.csv", _points(robots[k], true[k], _q(robots[k], 30, rng),
                                                 k, 10e-6, rng)) for k in range(2)]
    evaluated = []
    for k in range(2):
        assert main(["evaluate", str(out), held[k], "--base", robots[k].base, "--tip",
                     robots[k].tip, "--frames", str(frames), "--json"]) == 0
        evaluated.append(json.loads(capsys.readouterr().out)["errors"]["rms_mm"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["calibrate", urdf, *files, "--base", "base_link", "ctip", "--tip", "atip",
                     "btip", "--method", "ls", "--out", str(tmp_path / "V.urdf"),
                     "--validate", *held, "--report", str(tmp_path / "R.json"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)["validation"]
    assert [v["chain"] for v in summary] == ["base_link -> atip", "ctip -> btip"]
    for v, rms in zip(summary, evaluated):
        assert v["errors"]["after"]["rms_mm"] == pytest.approx(rms, rel=1e-9)
        assert v["errors"]["before"]["rms_mm"] > 10 * rms
    whole = json.loads((tmp_path / "R.json").read_text())
    report = whole["validation"]
    assert [v["source"] for v in report] == held
    # the report's residuals are every set's, each sample with its set (not the first's alone)
    res, sets = whole["residuals"], whole["sets"]
    assert res["set"] == [k + 1 for k, s in enumerate(sets) for _ in s["residuals"]["row"]]
    assert res["row"] == [r for s in sets for r in s["residuals"]["row"]]
    assert res["error_mm"] == [e for s in sets for e in s["residuals"]["error_mm"]]


def _plane_touches(robot, true, n, rng, height, tool):
    """Joint values (n, ...) putting ``tool`` (tip frame) of the true robot on the plane
    z = height of the base frame (inverse kinematics from random starts)."""
    out = []
    while len(out) < n:
        q0 = _q(robot, 1, rng)[0]
        T = true.tip_poses(q0[None])[0]
        p = T[:3, 3] + T[:3, :3] @ tool
        q, ok = true.inverse_kinematics(np.r_[p[:2], height], tool, start=q0)
        if ok:
            out.append(q)
    return np.array(out)


def _shared_plane_sets(tmp_path, rng):
    from kincal.measurements.plane import PlaneData

    text, _ = random_tree(np.random.default_rng(3))
    path = tmp_path / "tree.urdf"
    path.write_text(text)
    robots = [Robot.load(path, base="ctip", tip=t) for t in ("atip", "btip")]  # one base
    ch, kin, true = _truth(robots, 1e-3, rng)
    sets = [PlaneData(joint_names=robots[k].joint_names, source=f"touches{k + 1}",
                      joint_values=_plane_touches(robots[k], true[k], 30, rng, 0.1, TOOLS[k]))
            for k in range(2)]
    return robots, sets


def test_shared_plane_one_set_of_plane_parameters(tmp_path):
    """Two chains from one base touching one plane: --shared-plane gives one plane.*, its
    Jacobian columns right (central differences), and noise-free touches are fitted to
    zero; chains from different bases are refused."""
    rng = np.random.default_rng(8)
    robots, sets = _shared_plane_sets(tmp_path, rng)
    o = CalibrationOptions(method="ls", shared_planes=True, tool_guess=tuple(TOOLS[0]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        p = CalibrationProblem(robots, sets, o)
        alone = CalibrationProblem(robots, sets, CalibrationOptions(method="ls"))
    names = p.layout.names
    assert "plane.d" in names and "set2.plane.d" not in names and "set2.tool.x" in names
    assert p.layout.size == alone.layout.size - 3
    at = [np.arange(p.layout.size)[p.layout.frame_slices[i]] for i in range(2)]
    for name in ("plane.rx", "plane.ry", "plane.d"):  # set 2 reads set 1's plane
        assert at[1][p.layout.frame_names(1).index(name)] == at[0][
            p.layout.frame_names(0).index(name)]
    u = p.start() / p.scale + rng.normal(0, 0.5, p.layout.size)
    f = p.residual_function()
    _, J = f(u, True)
    D = np.empty_like(J)
    for k in range(len(u)):
        e = np.zeros(len(u))
        e[k] = STEP
        D[:, k] = (f(u + e, False)[0] - f(u - e, False)[0]) / (2 * STEP)
    assert np.abs(J - D).max() < 1e-6 * max(1.0, np.abs(D).max())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = p.solve()
    assert max(s.after.max for s in res.sets) < 1e-6  # [mm]
    plane = [[s.frame(n) for n in ("plane.rx", "plane.ry", "plane.d")] for s in res.sets]
    assert plane[0] == plane[1]
    other = Robot.load(robots[0].source, base="atip", tip="btip")
    with pytest.raises(OptionError, match="--shared-plane: set 2 .* base 'atip'.* one base"):
        CalibrationProblem([robots[0], other], [sets[0], type(sets[1])(
            joint_names=other.joint_names, joint_values=_q(other, 30, rng))], o)



def test_gate_judges_every_chain_not_only_the_first(tmp_path):
    """A second chain whose own branch the data say is far from its URDF (another robot's
    arm: a private origin moved by a third of its reach) is refused by the corrections
    finding, though the first chain barely changes."""
    from kincal.models.geometry import chain_length

    robots, joints = _tree(tmp_path)
    rng = np.random.default_rng(5)
    g = robots[1].geometry
    shift = chain_length(g.joint_frames, g.T_base_tip) / 3
    T = robots[1].urdf_origins(("bj2",))["bj2"].copy()
    T[:3, 3] += shift * np.array([0.6, 0.0, 0.8])
    true = (robots[0], robots[1].with_origins({"bj2": T}))
    sets = [_points(robots[k], true[k], _q(robots[k], 40, rng), k, 10e-6, rng) for k in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(list(robots), sets, method="ls")
    kinds = [f.kind for f in res.plausibility.findings]
    assert "corrections" in kinds, res.plausibility.describe()
    ev = res.plausibility.evidence
    assert ev.change_rms_mm > 0.1 * ev.reach_m * 1e3
    # the first chain alone moves far less: the finding is the second chain's
    first = robots[0].with_origins(res.corrected.urdf_origins(tuple(res.error_model.joint_names)))
    q = _q(robots[0], 300, np.random.default_rng(0))
    from kincal.rotations import aligned_distances as _aligned_distances

    d = _aligned_distances(robots[0].tip_poses(q)[:, :3, 3], first.tip_poses(q)[:, :3, 3])
    assert np.sqrt(np.mean(d ** 2)) * 1e3 < 0.5 * ev.change_rms_mm


def test_shared_flush_plane_moves_a_contact_point_only_along_its_face_normal(tmp_path,
                                                                             capsys):
    """Two flush files touching one table (--shared-plane): their contact heights along the
    face normal differ by what the data see; the contact points' other components stay at
    --tool-offset. The tool point's x came first in the selection, its column the face
    normal's tiny x component times the heights' offset: kept in place of tool.z, it ran
    off by half a metre (a false 'implausible' refusal here; with other data, a contact
    point silently wrong in FRAMES.json)."""
    from kincal import models
    from kincal.frames_file import CellFrames
    from kincal.measurements.sets import to_csv_text
    from kincal.planning.kind_simulation import simulate_flush, tool_points

    robot = Robot.load("ec66", tip="flange")
    model = models.build("offsets", robot.geometry)
    rng = np.random.default_rng(5)
    lo, hi = robot.geometry.ranges()
    contact = np.array([0.01, 0.02, 0.1, 0.0, 0.0])
    q0 = rng.uniform(lo, hi, size=(200, robot.geometry.n))
    table = [0.0, 0.0, float(np.mean(tool_points(model, model.nominal, q0, contact[:3])[:, 2]))]
    paths = []
    for k in range(2):  # two sessions on the one table, 0.01 mm / 0.01 deg of noise
        cand = rng.uniform(lo, hi, size=(1500, robot.geometry.n))
        data = simulate_flush(model, model.nominal, contact, [table], cand, 25, 1e-5, 0.01,
                              rng, limits=(lo, hi))
        paths.append(tmp_path / f"session{k + 1}.csv")
        paths[-1].write_text(to_csv_text(data))
    out = tmp_path / "frames.json"
    assert main(["calibrate", "ec66", *map(str, paths), "--on-plane", "--flush",
                 "--shared-plane", "--tool-offset", "0.01", "0.02", "0.1", "--model", "offsets",
                 "--out", str(tmp_path / "c.urdf"), "--frames-out", str(out), "-q"]) == 0, \
        capsys.readouterr().err
    for s in CellFrames.read(out).sets:
        assert s.value("tool.x") == 0.01 and s.value("tool.y") == 0.02
        assert abs(s.value("tool.z") - 0.1) < 1e-4  # [m]: one table, one face


def test_added_frames_hang_on_each_sets_own_chain(tmp_path, capsys):
    """--add-frames with two chains of other bases and tips: set 2's measurement frame is a
    child of its base link and its tool point of its tip link (both hung on set 1's before),
    so that the written URDF alone, from one added frame to the other, predicts each set's
    measured points."""
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(4)
    ch, kin, true = _truth(robots, 1e-3, rng)
    qs = [_q(robots[k], 40, rng) for k in range(2)]
    sets = [_points(robots[k], true[k], qs[k], k) for k in range(2)]
    files = [_csv(tmp_path / f"s{k}.csv", s) for k, s in enumerate(sets)]
    out = tmp_path / "CAL.urdf"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["calibrate", str(robots[0].source), *files, "--base", "base_link", "ctip",
                     "--tip", "atip", "btip", "--method", "ls", "--add-frames", "--out",
                     str(out), "--quiet"]) == 0
    text = out.read_text()
    for suffix, base, tip in (("", "base_link", "atip"), ("_set2", "ctip", "btip")):
        for name, link in (("kincal_measurement_frame", base), ("kincal_tool_point", tip)):
            assert f'<joint name="{name}{suffix}_joint" type="fixed">\n    <parent link="{link}"/>' \
                in text.replace("  <joint", "<joint")
    for k, suffix in enumerate(("", "_set2")):
        seen = Robot.load(out, base="kincal_measurement_frame" + suffix,
                          tip="kincal_tool_point" + suffix)
        predicted = seen.tip_poses(qs[k])[:, :3, 3]
        assert np.abs(predicted - sets[k].positions).max() < 1e-6  # [m], noise-free points


def test_analyze_takes_several_chains_as_calibrate_does(tmp_path, capsys):
    """kincal analyze with one --base/--tip per file (an argparse usage error before): the
    parameters it says the data identify are those the calibration identifies."""
    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(4)
    ch, kin, true = _truth(robots, 1e-3, rng)
    files = [_csv(tmp_path / f"s{k}.csv", _points(robots[k], true[k], _q(robots[k], 40, rng),
                                                  k, 10e-6, rng)) for k in range(2)]
    chains = ["--base", "base_link", "ctip", "--tip", "atip", "btip"]
    assert main(["analyze", str(robots[0].source), *files, *chains, "--model", "placement",
                 "--json"]) == 0
    kept = set(json.loads(capsys.readouterr().out)["identifiability"]["kept"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["calibrate", str(robots[0].source), *files, *chains, "--model",
                     "placement", "--out", str(tmp_path / "c.urdf"), "--json"]) == 0
    identified = {p["name"] for p in json.loads(capsys.readouterr().out)["parameters"]
                  if p["status"] == "identified"}
    assert kept == identified and any(n.startswith("set2.") for n in kept)
    assert main(["analyze", str(robots[0].source), *files, *chains, "--accuracy-map", "0", "0",
                 "0", "0.1"]) == 1
    assert "describe one chain; this analysis has several" in capsys.readouterr().err


def test_joints_held_are_shown_in_their_own_chains_units():
    """The summary's line of joints held during the measurements (--joint-value) reads each
    set's joints on that set's chain: a prismatic joint of the second chain, absent from the
    first, is shown in mm (it was looked up on the first chain's joints and shown as an
    angle: 0.1 m as 5.73 deg)."""
    from types import SimpleNamespace as NS

    from kincal.identification.result_text import held

    def robot(names, kinds):
        return NS(joint_names=names, geometry=NS(kinds=kinds))

    first, second = robot(("j1", "j2"), ("revolute", "revolute")), robot(
        ("j1", "slide"), ("revolute", "prismatic"))
    sets = [NS(data=NS(fixed_joints=(("j2", 0.5),))), NS(data=NS(fixed_joints=(("slide", 0.1),)))]
    result = NS(sets=sets, robot=first, chains=NS(robots=(first, second)))
    assert held(result) == [
        "  set 1: joints held during the measurements (not in the file): j2 = 28.6479 deg",
        "  set 2: joints held during the measurements (not in the file): slide = 100 mm"]


def test_each_chains_backlash_and_compliance_terms_stay_with_it():
    """FRAMES.json of two chains holds every chain's terms; the frames of one chain (what
    kincal evaluate and compensate read) keep that chain's, so a compliance term of the other
    arm's leg no longer refuses the file ("no chain joint ... for a compliance term"); a
    term on no chain of the file is still refused."""
    from kincal.errors import DataError

    left = ("l1", "t1", "l2")
    right = ("r1", "t1", "r2")
    f = CellFrames("robot", "", "lb", "lt", left, (
        FlushSetFrames("a.csv", "lb", "lt", left), FlushSetFrames("b.csv", "rb", "rt", right)),
        backlash={"l2": 1e-3, "r2": 2e-3}, compliance={"l1": 1e-3, "t1": 2e-3, "r1": 3e-3})
    for (base, tip), joints, back in ((("lb", "lt"), {"l1", "t1"}, {"l2"}),
                                      (("rb", "rt"), {"t1", "r1"}, {"r2"})):
        mine = f.for_chain(base, tip)
        assert set(mine.compliance) == joints and set(mine.backlash) == back
        assert [s.source for s in mine.sets] == (["a.csv"] if base == "lb" else ["b.csv"])
    odd = CellFrames("robot", "", "lb", "lt", left, f.sets, compliance={"x9": 1e-3})
    assert odd.for_chain("rb", "rt").compliance == {"x9": 1e-3}

    class _Robot:
        model_name, base, tip, joint_names, name = "robot", "rb", "rt", right, "robot"

    with pytest.raises(DataError, match="no chain joint 'x9'"):
        odd.for_chain("rb", "rt").check_chain(_Robot())


def test_the_frames_of_a_chain_are_its_own_sets_only():
    """FRAMES.json of flush touches on the file's chain (EC66 lb -> lt: flange) and points on
    another (rb -> rt: link_5): evaluate and compensate on the file's chain read the other
    chain's measurement frame and tool point (a point in another tip frame) as its own,
    rc 0 (EC66: 67 mm mean error from evaluate, 14 deg joint changes from compensate). The
    file's chain now has its own sets only, and no measurement frame: refused, naming the
    chain that has one."""
    from kincal.errors import DataError
    from kincal.frames_file import SetFrames

    left, right = ("l1", "t1", "l2"), ("r1", "t1", "r2")
    names = tuple(f"base.{c}" for c in ("x", "y", "z", "rx", "ry", "rz")) + tuple(
        f"tool.{c}" for c in "xyz")
    point = SetFrames("point", "b.csv", names, (0.8, 0.3, -0.2, 0.0, 0.0, 1.0, 0.05, 0.02, 0.08),
                      "rb", "rt", right)
    f = CellFrames("robot", "", "lb", "lt", left, (FlushSetFrames("a.csv", "lb", "lt", left),
                                                   point))
    with pytest.raises(DataError, match=r"no measurement set on the chain lb -> lt .*kinds "
                                        r"flush.*its point or pose sets are on rb -> rt"):
        f.located()
    with pytest.raises(DataError, match=r"<frames> holds the frames of 2 chains \(lb -> lt, "
                                        r"rb -> rt\): give --base and --tip"):
        f.for_chain(None, None)  # which chain the data are on: not for the first to say
    for base, tip in (("lb", "lt"), (None, "lt")):
        mine = f.for_chain(base, tip)
        assert [s.source for s in mine.sets] == ["a.csv"]
        with pytest.raises(DataError, match="no measurement set on the chain lb -> lt"):
            mine.located()
    assert f.for_chain("rb", "rt").located() is point
    assert f.for_chain(None, "rt").tools.tolist() == [[0.05, 0.02, 0.08]]
    # two chains from one base: --base alone names both (it took the first chain's frames)
    arms = CellFrames("robot", "", "lb", "lt", left, (FlushSetFrames("a.csv", "lb", "lt", left),
                                                      FlushSetFrames("c.csv", "lb", "rt", right)))
    with pytest.raises(DataError, match=r"2 chains \(lb -> lt, lb -> rt\), 2 of them with "
                                        r"--base lb: give --base and --tip"):
        arms.for_chain("lb", None)
    assert [s.source for s in arms.for_chain(None, "rt").sets] == ["c.csv"]


def FlushSetFrames(source, base, tip, joints):
    """A flush set's frames on the chain base -> tip."""
    from kincal.frames_file import SetFrames

    return SetFrames("flush", source, ("plane.rx", "plane.ry", "plane.d"), (0.0, 0.0, 0.7),
                     base, tip, joints)


@pytest.mark.parametrize("prismatic_first", [False, True])
def test_tool_axis_note_on_chains_ending_in_a_prismatic_joint_and_a_revolute_one(
        prismatic_first, rng):
    """Point sets on two chains, one ending in a prismatic joint (a finger), one in a revolute
    joint: each set's tool points are judged against its own chain's last axis. The command
    line crashed with a TypeError (None > float: the prismatic chain's distances, None, were
    compared with the other's) when the revolute chain came first (TIAGo, the head and a
    fingertip); a tool point on the revolute chain's last axis is still named."""
    arm, finger = (Robot.load("panda", base="panda_link0", tip=t)
                   for t in ("panda_link7", "panda_leftfinger"))
    robots = (finger, arm) if prismatic_first else (arm, finger)
    q = [_q(r, 40, rng) for r in robots]
    sets = [Measurements(joint_names=r.joint_names, joint_values=q[k],
                         positions=r.tip_poses(q[k])[:, :3, 3], source=f"chain{k + 1}")
            for k, r in enumerate(robots)]
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        notes = CalibrationProblem(list(robots), sets, CalibrationOptions()).analyze().notes
    assert any("from the axis of panda_joint7" in n for n in notes)  # its tool point: 0
    assert any("from the axis of panda_joint7" in str(w.message) for w in seen)


def test_every_report_names_every_chain(tmp_path):
    """The console summary named both chains of a two-chain calibration, the HTML page's
    title and robot row the first alone; all reports now say one thing (chains_text)."""
    from kincal.export.html_report import html_report

    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(0)
    sets = [_points(robots[k], robots[k], _q(robots[k], 40, rng), k, 1e-5, rng)
            for k in range(2)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = calibrate(list(robots), sets, CalibrationOptions(method="ls"))
    both = "base_link -> atip, ctip -> btip"
    assert result.chains_text() == both and f"({both})" in result.summary().splitlines()[0]
    page = html_report(result)
    assert page.count(f"({both})".replace(">", "&gt;")) >= 3  # <title>, <h1>, the robot row


def test_unit_clue_of_points_on_a_second_chain_after_plane_touches_on_the_first(tmp_path):
    """The gate's unit clue (measured spread against the nominal tool point's) takes the first
    set that measures positions: here points on the second chain after plane touches on the
    first. It was computed with the first chain's kinematics: a traceback where the chains'
    joint counts differ (IndexError; TIAGo-like: flush touches at the gripper, points at a
    shorter chain's tip), a wrong ratio otherwise. Now the set's own chain, as for the
    points calibrated alone."""
    from kincal.measurements.plane import PlaneData

    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(7)
    touches = PlaneData(joint_names=robots[0].joint_names, source="touches",
                        joint_values=_plane_touches(robots[0], robots[0], 30, rng, 0.1,
                                                    TOOLS[0]))
    points = _points(robots[1], robots[1], _q(robots[1], 40, rng), 1, 10e-6, rng)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        both = calibrate(list(robots), [touches, points], method="ls")
        alone = calibrate(robots[1], points, method="ls")
    ratio = both.plausibility.evidence.length_ratio
    assert np.isfinite(ratio) and ratio == pytest.approx(
        alone.plausibility.evidence.length_ratio, rel=1e-12)


def test_diagnosis_names_backlash_of_a_shared_joint_over_two_chains(tmp_path):
    """Backlash planted on a trunk joint both chains traverse (the tool poses are those of
    q + b g, the files record q): the residual diagnosis, one test over the two chains'
    sets, names that joint with its size (it said nothing with several chains); the same
    poses without the play: nothing named."""
    from kincal.identification.diagnosis import diagnose
    from kincal.models.backlash import approach_directions

    robots, _ = _tree(tmp_path)
    rng = np.random.default_rng(11)
    half = np.radians(0.1)
    found = []
    for play in (half, 0.0):
        sets = []
        for k in range(2):
            q = _q(robots[k], 80, rng)
            moved = q.copy()
            j = robots[k].joint_names.index("tj1")
            moved[:, j] += play * approach_directions(q)[:, j]
            d = _points(robots[k], robots[k], moved, k, 2e-5, rng)
            sets.append(Measurements(joint_names=robots[k].joint_names, joint_values=q,
                                     positions=d.positions, source=d.source))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            found.append(diagnose(calibrate(list(robots), sets, method="ls")))
    f, clean = found
    assert (f.joint, f.cause) == ("tj1", "backlash") and f.rms_deg is None
    assert abs(f.size) == pytest.approx(0.1, rel=0.15) and f.rms_mm[1] < f.rms_mm[0]
    assert clean is None


def test_a_shared_plane_that_shares_nothing_is_refused(tmp_path, capsys):
    """--shared-plane with one contact file, or with files naming no plane alike (a
    `plane` column's 1 beside a file without the column, `plane`), was taken and shared
    nothing: the calibration was the one without it."""
    contacts = tmp_path / "c.csv"
    assert main(["simulate", "ec66", "--kind", "plane", "--poses", "30", "--out",
                 str(contacts), "-q"]) == 0
    rows = [line.split(",") for line in contacts.read_text().splitlines()
            if not line.startswith("#")]
    table = tmp_path / "t.csv"  # plane 1's rows without the plane column
    table.write_text("".join(",".join(r[:-1]) + "\n" for r in rows
                             if r is rows[0] or float(r[-1]) == 1))
    capsys.readouterr()
    for files, named in (([contacts], "(one contact file, set 1 (" + str(contacts)
                          + "): plane1 plane2 plane3)"),
                         ([contacts, table], "(set 1 (" + str(contacts) + "): plane1 plane2 "
                          "plane3; set 2 (" + str(table) + "): plane)")):
        assert main(["calibrate", "ec66", *map(str, files), "--on-plane", "--shared-plane",
                     "--out", str(tmp_path / "c.urdf")]) == 1
        err = capsys.readouterr().err.strip().splitlines()
        assert err == ["kincal: error: --shared-plane: no plane is named in two contact "
                       "files, nothing to share " + named + "; a plane column's numbers "
                       "name the same plane in every file, a file without one touches "
                       "'plane'"]
    assert not (tmp_path / "c.urdf").exists()
    robot = Robot.load("ec66", tip="flange")  # the API's path: the same refusal
    from kincal.measurements.sets import read_set_file

    data = read_set_file(contacts, robot.joint_names, on_plane=True)
    with pytest.raises(OptionError, match="^--shared-plane: no plane is named in two"):
        CalibrationProblem(robot, [data], CalibrationOptions(shared_planes=True))
