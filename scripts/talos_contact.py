"""TALOS flush table contacts (real robot): kincal's held-out accuracy beside FIGAROH's.

Reads ``../shared/data/talos_contact/`` at run time (21 training touches of 2022-10-28, 9
validation touches of 2022-11-07; see its README), calibrates the chain from the left sole
to the left gripper with the command line a user would type::

    kincal calibrate talos_full_v2.urdf left_train.csv --base left_sole_link \\
        --tip gripper_left_base_link --on-plane --flush --tool-offset 0 0 -0.12 \\
        --out CAL.urdf --frames-out FRAMES.json

and judges the files it wrote on the other day's touches, as an independent check would:
the corrected URDF (through Pinocchio), the contact point and face tilt from FRAMES.json,
the table plane fitted (SVD) through the training touches' contact points. Held-out RMS of
the validation touches' height above that plane [mm] and of the face's two tilts against its
normal, roll about the contact frame's x axis and pitch about its y axis [deg].

The validation file's header lacks the 4 leading empty names of the training file's, so
kincal refuses it as it is ("the names look shifted"); the script reads its rows by position
into a file with the training header, as its README says to.

Usage: python scripts/talos_contact.py [--variants] [--loo]   (about 3 s; --variants: about
       35 s; --loo: each row also by leave-one-out on the training day, about 17 min)
       python scripts/talos_contact.py --two-chains [SEEDS] [--urdf-alone] [--torso-turn DEG]
       (about 3 s per seed; --urdf-alone: FRAMES.json's face tilts not applied to the held-out
       touches; --torso-turn: the right chain's truth turns the shared torso_2 origin by DEG
       more about x than the left's)
       python scripts/talos_contact.py --subsets 8,10,12,15,18 [--reps 4]   (about 1 min)

--subsets: how many touches the default needs. For each size, --reps random subsets of
the 21 training touches (seeded), each calibrated with the default command and judged on
the held-out touches as above; per run the equations, the identifiable parameters, and
whether kincal warned that none was left over (no more equations than identifiable
parameters) or refused the result.

--two-chains: the two arms together against each alone, on simulated touches (we have the
left chain's real data only). The simulated TALOS is the nominal one with errors planted
on every origin of both chains (1 mm, 0.3 deg; twice that on the shared torso); each
chain touches its own table (where the nominal robot's touches put it): the left with the
postures of the real touches, the right with their mirror images, each moved (Newton,
least joint motion) until the contact frame lies flush up to the planted noise of its
file, the left as kincal estimates it on the real touches, the right either quieter or
5x noisier (another instrument); held-out: the other day's postures, noise-free. Three
calibrations per seed: each chain alone (the first command of issue 18), both together
(the second), and both together with one noise for all rows (the same sigma stated for
both files, as kincal weighed them before it estimated a noise per file and kind of row).

The default row is judged again after one tilt of the table (two angles) fitted to the
held-out touches themselves: what the table's turn between the days leaves. The nominal and
the default rows are also read as the data README's figures are (roll and pitch of the
contact frame in a frame of the plane, less their mean over the training touches): that
reading gives the README's nominal 1.27 / 1.56 deg.

The mirrored rows: the real touches' mirror image on the right chain (the same problem
mirrored: the left chain's figures are expected, to rounding), from the left sole through
the other leg, and with the real left touches in one calibration of both chains.

The last two lines: how well the log's leg joint values close the loop between the feet
(both soles flat on the floor) on the nominal model, on each day's touches.

--variants adds other penalty and model choices (among them compliance terms on the stance
leg, whose joints carry the robot's weight: FRAMES.json's compliance is applied to the
held-out touches, with the gravity torques of the chain at each touch, the joints off the
chain at zero), and a floor: the defaults fitted on both
days together and judged in sample on the second day's touches (with the plane through
every touch), which no out-of-sample prediction can be expected to beat. Each compliance
row is judged again on the URDF alone (FRAMES.json's compliance not applied, as a reader
of the URDF would) and on the URDF with the deflection at the training touches' mean
gravity torque folded into the joints, and each row calibrated by the evidence gives its
log evidence [nats] (the summary's, comparable between rows that weigh the data alike).
The default (and each row with --fix) is judged again on the URDF's tip frame and the
contact point alone (FRAMES.json's face tilt not applied), the default also against
FRAMES.json's own plane; two rows take a robust loss (--robust huber, cauchy); and a
second floor fits both days with a plane per
day (a ``plane`` column), judged on the second day's touches against its own plane: how
much of the held-out error is the table moving against the sole between the days.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import sys
import tempfile
import warnings
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "talos_contact"
BASE, TIP = "left_sole_link", "gripper_left_base_link"
LEG = tuple(f"leg_left_{k}_joint" for k in range(1, 7))  # the stance leg: it carries the body
FIGAROH = (5.76, 0.42, 0.49)  # published held-out RMS: height [mm], roll, pitch [deg]


def talos_urdf() -> Path:
    """example-robot-data's talos_full_v2.urdf (a dependency of kincal)."""
    from kincal.descriptions import resolve

    return resolve("talos").urdf


def joint_rows(path: Path) -> tuple[list[str], np.ndarray]:
    """(joint names, (N, 32) values) of a TALOS log, rows read by position: 5 metadata
    fields, then the joints in the order of the training file's header."""
    names = [h for h in next(csv.reader(open(DATA / "left_train.csv")))[5:] if h.strip()]
    rows = [r for r in csv.reader(open(path)) if r and r[0] == "gripper"]
    return names, np.array([[float(v) for v in r[5:5 + len(names)]] for r in rows])


def write_joint_csv(path: Path, names, values, planes=None) -> None:
    """A joint-column file; planes: (N,) whole numbers, the ``plane`` column (None: none)."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(list(names) + ([] if planes is None else ["plane"]))
        w.writerows([[repr(float(v)) for v in row] + ([] if planes is None else [str(k)])
                     for k, row in zip([None] * len(values) if planes is None else planes,
                                       values)])


def held_out(urdf: Path, frames_path: Path, q_train: np.ndarray, q_valid: np.ndarray,
             names, base: str = BASE, tip: str = TIP, k: int = 0,
             compliance: bool | str = True, face_tilt: bool = True,
             plane: str | None = None, table_tilt: bool = False,
             training_mean: bool = False) -> tuple[float, float, float]:
    """(height [mm], roll [deg], pitch [deg]) RMS on the validation touches, from the files
    a calibration wrote (see the module notes): the chain base -> tip, set k of FRAMES.json;
    compliance False: FRAMES.json's compliance terms not applied (the URDF alone); "mean":
    the URDF with their deflection at the training touches' mean gravity torque added to
    every touch's joint values (the compliance folded into the URDF at the mean load);
    face_tilt False: FRAMES.json's contact frame tilts (tool.rx .ry) not applied either (the
    URDF's tip frame and the contact point alone); plane: judged against FRAMES.json's
    plane of that label (``plane<label>.*``) instead of the plane fitted to q_train;
    table_tilt: the validation touches' tilts after one tilt of the plane (two angles)
    fitted to themselves: what is left when the table's turn between the days is taken
    out (height: NaN); training_mean: roll and pitch read as the URDF's roll and pitch of
    the contact frame in a frame of the plane (its z the normal, its x the base's x laid
    on the plane), less their mean over the training touches (the contact frame's tilt
    taken from the training touches instead of FRAMES.json)."""
    from kincal.frames_file import CellFrames
    from kincal.measurements.flush import tilt_angles
    from kincal.measurements.plane import fit_plane, normal
    from kincal.robot import Robot
    from kincal.rotations import base_rotation, matrix_to_rpy

    robot = Robot.load(urdf, base=base, tip=tip)
    idx = [list(names).index(j) for j in robot.joint_names]
    cell = CellFrames.read(frames_path)
    s = cell.sets[k]
    c = np.array([cell.compliance.get(j, 0.0) if compliance else 0.0
                  for j in robot.joint_names])
    fold = None
    if compliance == "mean":  # a constant deflection: c times the training touches' mean
        fold = c * robot.gravity_torques(q_train[:, idx]).mean(axis=0)
    t = np.array([s.value(f"tool.{c}") for c in "xyz"])
    tilt = [s.value(f"tool.{c}") if s.has(f"tool.{c}") and face_tilt else 0.0
            for c in ("rx", "ry")]
    R_c = base_rotation(tilt[0], tilt[1], 0.0)

    def contact(q):
        q = q[:, idx]
        if fold is not None:
            q = q + fold
        elif c.any():  # FRAMES.json's compliance terms: the joints sit at q + c tau(q)
            q = q + c * robot.gravity_torques(q)
        T = robot.tip_poses(q)
        return T[:, :3, 3] + T[:, :3, :3] @ t, T[:, :3, :3] @ R_c

    if plane is None:
        P, A = contact(q_train)
        n, d, _ = fit_plane(P)
        if np.mean(A[:, :, 2] @ n) < 0:  # the normal on the face's side
            n, d = -n, -d
    else:
        n = normal(s.value(f"plane{plane}.rx"), s.value(f"plane{plane}.ry"))
        d = s.value(f"plane{plane}.d")
    P, A = contact(q_valid)
    roll, pitch = tilt_angles(np.einsum("nji,j->ni", A, n))
    if training_mean:
        x = np.array([1.0, 0.0, 0.0]) - n[0] * n
        x /= np.linalg.norm(x)
        R_p = np.stack([x, np.cross(n, x), n], axis=1)

        def angles(A):
            return np.array([matrix_to_rpy(R_p.T @ R)[:2] for R in A])

        roll, pitch = (angles(A) - angles(contact(q_train)[1]).mean(axis=0)).T
    if table_tilt:  # n + a u + b w, the two angles by linear least squares on the tilts
        u = np.cross(n, [1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.cross(n, [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        w = np.cross(n, u)
        M = np.stack([np.einsum("nji,j->ni", A, e)[:, :2].ravel() for e in (u, w)], axis=1)
        v = np.einsum("nji,j->ni", A, n)[:, :2].ravel()
        ab = np.linalg.lstsq(M, -v, rcond=None)[0]
        n = n + ab[0] * u + ab[1] * w
        roll, pitch = tilt_angles(np.einsum("nji,j->ni", A, n / np.linalg.norm(n)))
        P = np.full(P.shape, np.nan)

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x))))

    return rms(P @ n - d) * 1e3, float(np.degrees(rms(roll))), float(np.degrees(rms(pitch)))


def nominal_frames(folder: Path, urdf: Path) -> Path:
    """A FRAMES.json with the nominal contact point (0, 0, -0.12) m and no tilt."""
    from kincal.frames_file import CellFrames, SetFrames

    path = folder / "nominal_frames.json"
    frames = CellFrames("", "", BASE, TIP, (), (SetFrames(
        "flush", "nominal", ("tool.x", "tool.y", "tool.z"), (0.0, 0.0, -0.12)),))
    path.write_text(frames.dumps())
    return path


def calibrate(folder: Path, urdf: Path, train, tag: str, *extra: str, bases=(BASE,),
              tips=(TIP,)):
    """kincal calibrate on the file(s) ``train`` (one path or a list, one chain each)."""
    from kincal.cli.main import main

    out, frames = folder / f"{tag}.urdf", folder / f"{tag}_frames.json"
    files = [str(f) for f in (train if isinstance(train, (list, tuple)) else [train])]
    argv = ["calibrate", str(urdf), *files, "--base", *bases, "--tip", *tips, "--on-plane",
            "--flush", "--tool-offset", "0", "0", "-0.12", "--out", str(out), "--frames-out",
            str(frames), "--json", *extra]
    summary = io.StringIO()
    with warnings.catch_warnings(), redirect_stdout(summary), redirect_stderr(io.StringIO()):
        warnings.simplefilter("ignore")
        code = main(argv)
    if code != 0:
        sys.exit(f"talos_contact: kincal {' '.join(argv)} failed ({code})")
    evidence = json.loads(summary.getvalue()).get("evidence")
    LOG_EVIDENCE[tag] = math.nan if evidence is None else evidence["log_evidence"][-1]
    return out, frames


LOG_EVIDENCE: dict[str, float] = {}  # [nats] per calibration tag: the evidence's last

# ------------------------------------------------------------------ two chains (simulated)
RIGHT_BASE, RIGHT_TIP = "right_sole_link", "gripper_right_base_link"
CONTACT = np.array([0.0, 0.0, -0.12, np.radians(0.5), np.radians(-0.3)])  # x y z [m], rx ry
# planted errors of the simulated robot: every origin of both chains, twice on the torso
PLANTED_MM, PLANTED_DEG, TORSO = 1.0, 0.3, 2.0
# noise (height [mm], tilt [deg]) of each file: the left as kincal estimates it on the real
# left touches (variance components: 0.91 mm, 0.45 deg), the right another instrument's
NOISE = {"right quieter": ((0.9, 0.45), (0.5, 0.25)),
         "right 5x noisier": ((0.9, 0.45), (4.5, 2.25))}


def mirror(urdf: Path, names) -> np.ndarray:
    """(32, 32) the matrix that turns a row of joint values into its mirror image (left and
    right chains swapped, through the soles' xz planes): joint by joint, the right joint
    and the sign whose motion is the mirror image of the left joint's (nominal TALOS,
    found numerically); torso and head joints keep or flip their sign likewise."""
    from kincal.robot import Robot

    chains = {side: Robot.load(urdf, base=f"{side}_sole_link", tip=f"gripper_{side}_base_link")
              for side in ("left", "right")}
    M = np.diag([1.0, -1.0, 1.0])
    out = np.zeros((len(names), len(names)))
    for a, b in (("left", "right"), ("right", "left")):
        ca, cb = chains[a], chains[b]
        # the grippers' frames differ by a constant turn besides the mirror
        Ra, Rb = (c.tip_poses(np.zeros((1, c.geometry.n)))[0, :3, :3] for c in (ca, cb))
        C = (M @ Ra @ M).T @ Rb
        for j, name in enumerate(ca.joint_names):
            other = name.replace(a, b)
            qa = np.zeros((1, ca.geometry.n))
            qa[0, j] = 0.3
            Ta = ca.tip_poses(qa)[0]
            errors = []
            for sign in (1.0, -1.0):
                qb = np.zeros((1, cb.geometry.n))
                qb[0, list(cb.joint_names).index(other)] = 0.3 * sign
                Tb = cb.tip_poses(qb)[0]
                errors.append(np.abs(Tb[:3, 3] - M @ Ta[:3, 3]).max()
                              + np.abs(Tb[:3, :3] - M @ Ta[:3, :3] @ M @ C).max())
            if min(errors) > 1e-6:
                sys.exit(f"talos_contact: {name} has no mirror image in {other}")
            out[names.index(other), names.index(name)] = 1.0 if errors[0] < errors[1] else -1.0
    for j, name in enumerate(names):  # off both chains (head, grippers): kept as they are
        if not out[:, j].any():
            out[j, j] = 1.0
    return out


def simulated_touches(model, kin, q_rows, names, robot, plane, noise, rng, source):
    """(N, 32) rows: q_rows with the chain's joints moved (Newton, least joint motion) until
    the contact frame lies flush on ``plane`` of the simulated robot ``kin``, up to the
    planted noise (height [mm], tilt [deg]) in the touch itself."""
    from kincal.planning.kind_simulation import simulate_flush

    idx = [names.index(j) for j in robot.joint_names]
    out = np.repeat(q_rows[:1], len(q_rows), axis=0)
    d = simulate_flush(model, kin, CONTACT, plane[None], q_rows[:, idx], len(q_rows),
                       noise[0] * 1e-3, noise[1], rng, source=source)
    out[:, idx] = d.joint_values
    return out


def two_chains(urdf: Path, seeds: int, face_tilt: bool = True,
               torso_turn: float = 0.0) -> list[tuple]:
    """Together against alone on simulated TALOS touches, per seed and noise case: rows
    (case, seed, chain, alone (h, roll, pitch), together (h, roll, pitch)). torso_turn
    [deg]: the right chain's truth has torso_2_joint's origin turned by that much more
    about x than the left's (data that disagree on the shared torso)."""
    from kincal.identification.chains import Chains
    from kincal.measurements.flush import FlushData, FlushKind
    from kincal.robot import Robot

    names, q_train = joint_rows(DATA / "left_train.csv")
    _, q_valid = joint_rows(DATA / "left_validation.csv")
    names = list(names)
    arms = [Robot.load(urdf, base=b, tip=t) for b, t in ((BASE, TIP), (RIGHT_BASE, RIGHT_TIP))]
    ch = Chains(arms, 2, "placement")
    Mq = mirror(urdf, names)
    touches = {0: (q_train, q_valid), 1: (q_train @ Mq.T, q_valid @ Mq.T)}
    planes = []
    for k, arm in enumerate(arms):  # each table where the nominal robot's touches put it
        q = touches[k][0][:, [names.index(j) for j in arm.joint_names]]
        data = FlushData(joint_names=arm.joint_names, joint_values=q)
        planes.append(FlushKind(ch.models[k], data).start(ch.models[k].nominal, CONTACT[:3])[:3])
    torso = np.array([n.startswith("torso_") for n in ch.model.names])
    rows = []
    for case, noise in NOISE.items():
        for seed in range(seeds):
            rng = np.random.default_rng(seed)
            size = np.where(ch.model.is_length, PLANTED_MM * 1e-3, np.radians(PLANTED_DEG))
            truth = ch.model.nominal + size * np.where(torso, TORSO, 1.0) * rng.normal(
                size=ch.model.size)
            with tempfile.TemporaryDirectory(prefix="kincal-talos2-") as tmp:
                folder = Path(tmp)
                sets = []
                for k, arm in enumerate(arms):
                    m, kin = ch.models[k], truth[ch.idx[k]].copy()
                    if k == 1:  # what the right chain alone sees of the torso
                        kin[list(m.names).index("torso_2_joint.rx")] += np.radians(torso_turn)
                    train = simulated_touches(m, kin, touches[k][0], names, arm, planes[k],
                                              noise[k], rng, f"chain{k}")
                    valid = simulated_touches(m, kin, touches[k][1], names, arm, planes[k],
                                              (0.0, 0.0), rng, f"chain{k} held out")
                    path = folder / f"{('LEFT', 'RIGHT')[k]}.csv"
                    write_joint_csv(path, names, train)
                    sets.append((path, train, valid, arm))
                files = [p for p, *_ in sets]
                both = calibrate(folder, urdf, files, "both", bases=(BASE, RIGHT_BASE),
                                 tips=(TIP, RIGHT_TIP))
                # one noise for all rows (kincal before variance components): the same
                # sigma stated for both files, the tilts weighed 1 deg against 1 mm
                one = calibrate(folder, urdf, files, "one", "--set-sigma-mm", "0.05", "0.05",
                                bases=(BASE, RIGHT_BASE), tips=(TIP, RIGHT_TIP))
                for k, (path, train, valid, arm) in enumerate(sets):
                    alone = calibrate(folder, urdf, path, f"alone{k}", bases=(arm.base,),
                                      tips=(arm.tip,))
                    rows.append((case, seed, ("left", "right")[k],
                                 held_out(*alone, train, valid, names, arm.base, arm.tip,
                                          face_tilt=face_tilt),
                                 held_out(*both, train, valid, names, arm.base, arm.tip, k,
                                          face_tilt=face_tilt),
                                 held_out(*one, train, valid, names, arm.base, arm.tip, k,
                                          face_tilt=face_tilt)))
    return rows


def mirrored(urdf: Path, folder: Path) -> list[tuple]:
    """Rows (label, height [mm], roll, pitch [deg], log evidence) of the real touches'
    mirror image (:func:`mirror`: the right arm and leg at the left's postures, mirrored)
    calibrated on the right chain with the default command: a robot and a table mirrored
    through the sole's xz plane are the same problem, so kincal must give the left chain's
    figures (nothing in it may favour one side of the tree). Then the same touches from the
    left sole (a chain through the other leg), and both chains together, the real left touches
    with the mirrored right ones: their torso errors are each other's mirror images, which
    one torso cannot be (the worst case for sharing: each chain's own origins absorb what
    they can)."""
    names, q_train = joint_rows(DATA / "left_train.csv")
    _, q_valid = joint_rows(DATA / "left_validation.csv")
    names = list(names)
    M = mirror(urdf, names)
    q_rt, q_rv = q_train @ M.T, q_valid @ M.T
    right = folder / "mirrored_right.csv"
    write_joint_csv(right, names, q_rt)
    left = DATA / "left_train.csv"  # the log as it is, as the default row reads it
    rows = []
    for k, (label, base) in enumerate((
            ("right sole -> right gripper", RIGHT_BASE),
            ("left sole -> right gripper (through the other leg)", BASE))):
        cal, frames = calibrate(folder, urdf, right, f"mirrored{k}", bases=(base,),
                                tips=(RIGHT_TIP,))
        rows.append((f"mirror image of the real touches, {label}",
                     *held_out(cal, frames, q_rt, q_rv, names, base, RIGHT_TIP),
                     LOG_EVIDENCE[f"mirrored{k}"]))
    both = calibrate(folder, urdf, [left, right], "mirrored_both", bases=(BASE, RIGHT_BASE),
                     tips=(TIP, RIGHT_TIP))
    for k, (chain, qt, qv, base, tip) in enumerate((("left", q_train, q_valid, BASE, TIP),
                                                    ("mirrored right", q_rt, q_rv, RIGHT_BASE,
                                                     RIGHT_TIP))):
        rows.append((f"  real left and mirrored right touches together, the {chain} chain",
                     *held_out(*both, qt, qv, names, base, tip, k), math.nan))
    return rows


def print_two_chains(rows) -> None:
    print("TALOS, two chains (left sole -> left gripper, right sole -> right gripper, sharing "
          "the torso), simulated: held-out RMS of noise-free touches of the other day's "
          "postures, alone vs together")
    print("| case | seed | chain | alone: height [mm], roll, pitch [deg] | together | "
          "together, one noise for all rows |")
    print("|---|---|---|---|---|---|")

    def cells(*runs):
        return " | ".join(f"{v[0]:.2f}, {v[1]:.3f}, {v[2]:.3f}" for v in runs)

    for case, seed, chain, *runs in rows:
        print(f"| {case} | {seed} | {chain} | {cells(*runs)} |")
    for case in NOISE:
        for chain in ("left", "right"):
            sel = np.array([runs for c, _, ch, *runs in rows if c == case and ch == chain])
            rms = np.sqrt(np.mean(np.square(sel), axis=0))
            print(f"| {case} | RMS over seeds | {chain} | {cells(*rms)} |")
    print("\nTogether minus alone, mean over the seeds +- its standard error (< 0: together "
          "better), and the seeds where together is at least as good:")
    print("| case | chain | height [mm] | roll [deg] | pitch [deg] |")
    print("|---|---|---|---|---|")
    for case in NOISE:
        for chain in ("left", "right"):
            sel = np.array([runs for c, _, ch, *runs in rows if c == case and ch == chain])
            d = sel[:, 1] - sel[:, 0]
            se = np.std(d, axis=0, ddof=1) / np.sqrt(len(d)) if len(d) > 1 else d[0] * np.nan
            print(f"| {case} | {chain} | " + " | ".join(
                f"{m:+.3f} +- {e:.3f} ({int(np.sum(x <= 0))}/{len(d)})"
                for m, e, x in zip(d.mean(axis=0), se, d.T)) + " |")



LOO: dict[str, np.ndarray] = {}  # --loo: (height, roll, pitch) RMS per variant


def leave_one_out(folder: Path, urdf: Path, names, q_train, extra, tag: str) -> np.ndarray:
    """(height [mm], roll [deg], pitch [deg]) RMS over the training touches, each judged as
    :func:`held_out` judges the other day's, by the calibration on the other touches."""
    out = []
    for i in range(len(q_train)):
        keep = np.arange(len(q_train)) != i
        path = folder / f"{tag}_loo{i}.csv"
        write_joint_csv(path, names, q_train[keep])
        cal, frames = calibrate(folder, urdf, path, f"{tag}_loo{i}", *extra)
        out.append(held_out(cal, frames, q_train[keep], q_train[~keep], names))
    return np.sqrt(np.mean(np.square(out), axis=0))


def plane_change(frames: Path) -> tuple[float, float]:
    """(angle [deg], offset change [mm]) between planes 1 and 2 of FRAMES.json."""
    from kincal.frames_file import CellFrames
    from kincal.measurements.plane import normal

    s = CellFrames.read(frames).sets[0]
    n1, n2 = (normal(s.value(f"plane{k}.rx"), s.value(f"plane{k}.ry")) for k in "12")
    return (float(np.degrees(np.arccos(min(1.0, float(n1 @ n2))))),
            (s.value("plane2.d") - s.value("plane1.d")) * 1e3)


def subset_sizes(text: str) -> list[int]:
    """--subsets SIZES: comma-separated touch counts, each 2 to 21 (the training file's)."""
    try:
        sizes = [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}")
    if not all(2 <= n <= 21 for n in sizes):
        raise argparse.ArgumentTypeError(f"each size must be 2 to 21 (the training touches), "
                                         f"got {text!r}")
    return sizes


def repetitions(text: str) -> int:
    """--reps N: 1 to 100."""
    if not text.isdigit() or not 1 <= int(text) <= 100:
        raise argparse.ArgumentTypeError(f"expected an integer from 1 to 100, got {text!r}")
    return int(text)


def subsets(urdf: Path, sizes, reps: int) -> None:
    """Print the --subsets table (see the module notes)."""
    from kincal.cli.main import main as kincal

    names, q_train = joint_rows(DATA / "left_train.csv")
    _, q_valid = joint_rows(DATA / "left_validation.csv")
    rng = np.random.default_rng(0)
    print(f"TALOS, the default on random subsets of the {len(q_train)} training touches "
          f"(seeded), held out on the {len(q_valid)} touches of the other day")
    print("| touches | subset | equations | identifiable | no equation left over | "
          "height [mm] | roll [deg] | pitch [deg] |")
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory(prefix="kincal-talos-") as tmp:
        folder = Path(tmp)
        for n in sizes:
            for rep in range(reps):
                idx = np.sort(rng.choice(len(q_train), n, replace=False))
                train = folder / f"t{n}_{rep}.csv"
                write_joint_csv(train, names, q_train[idx])
                out, frames = folder / f"c{n}_{rep}.urdf", folder / f"f{n}_{rep}.json"
                argv = ["calibrate", str(urdf), str(train), "--base", BASE, "--tip", TIP,
                        "--on-plane", "--flush", "--tool-offset", "0", "0", "-0.12", "--out",
                        str(out), "--frames-out", str(frames), "--json"]
                so, se = io.StringIO(), io.StringIO()
                with warnings.catch_warnings(), redirect_stdout(so), redirect_stderr(se):
                    code = kincal(argv)
                err = se.getvalue()
                spare = "no" if "identifiable parameters: none is left over" in err else "yes"
                cells = f"| {n} | {' '.join(str(i + 1) for i in idx)} |"
                if code != 0:
                    line = next(x for x in err.splitlines() if x.startswith("kincal: error:"))
                    print(f"{cells} | | | {line[len('kincal: error: '):][:60]}... | | |")
                    continue
                summary = json.loads(so.getvalue())
                m = 3 * n
                k = summary["identifiability"]["rank"]
                h = held_out(out, frames, q_train[idx], q_valid, names)
                print(f"{cells} {m} | {k} | {'warned' if spare == 'no' else 'no'} | "
                      f"{h[0]:.2f} | {h[1]:.3f} | {h[2]:.3f} |")


def feet_closure(urdf: Path, names, q: np.ndarray) -> tuple[float, float, float, float]:
    """How well the log's leg joint values close the loop between the feet on the nominal
    model: the right sole seen from the left through both legs at every touch, against its
    median place: (median, max) distance [mm] and (median, max) turn [deg]. Both soles stand
    flat on the floor; raw encoder readings of legs with real errors would not close it on
    the nominal model to the encoders' resolution."""
    from kincal.robot import Robot

    robot = Robot.load(urdf, base=BASE, tip="right_sole_link")
    T = robot.tip_poses(q[:, [list(names).index(j) for j in robot.joint_names]])
    p = T[:, :3, 3]
    dist = np.linalg.norm(p - np.median(p, axis=0), axis=1) * 1e3
    R0 = T[np.argmin(dist), :3, :3]
    cos = (np.einsum("ij,nij->n", R0, T[:, :3, :3]) - 1.0) / 2.0
    turn = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    return (float(np.median(dist)), float(dist.max()), float(np.median(turn)),
            float(turn.max()))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--variants", action="store_true",
                        help="also the other penalty and error model choices")
    parser.add_argument("--loo", action="store_true",
                        help="also judge each row by leave-one-out on the training day (each "
                        "touch predicted by the calibration on the other 20, the plane fitted "
                        "through their contact points; 21 more calibrations per row)")
    parser.add_argument("--urdf-alone", action="store_true",
                        help="with --two-chains: judge the held-out touches on the URDF's tip "
                        "frames and the contact points alone (FRAMES.json's face tilts not "
                        "applied)")
    parser.add_argument("--two-chains", type=int, nargs="?", const=5, default=0,
                        metavar="SEEDS", help="only the simulated two-chain study (left and "
                        "right arms together vs alone), over SEEDS seeds (default 5)")
    parser.add_argument("--torso-turn", type=float, default=0.0, metavar="DEG",
                        help="with --two-chains: the right chain's truth turns torso_2_joint's "
                        "origin by DEG more about x than the left's (chains that disagree on "
                        "the torso they share)")
    parser.add_argument("--subsets", metavar="SIZES", type=subset_sizes,
                        help="only the subset study: the "
                        "default on random subsets of these sizes of the training touches "
                        "(comma-separated, e.g. 8,10,12,15,18)")
    parser.add_argument("--reps", type=repetitions, default=4, metavar="N",
                        help="with --subsets: subsets per size (1 to 100)")
    args = parser.parse_args(argv)
    if not DATA.is_dir():
        sys.exit(f"talos_contact: {DATA} not found (the shared data sit beside the repository)")
    urdf = talos_urdf()
    if args.subsets:
        subsets(urdf, args.subsets, args.reps)
        return 0
    if args.two_chains:
        print_two_chains(two_chains(urdf, args.two_chains, not args.urdf_alone,
                                    args.torso_turn))
        return 0
    names, q_train = joint_rows(DATA / "left_train.csv")
    _, q_valid = joint_rows(DATA / "left_validation.csv")
    rows = [("FIGAROH (published)", *FIGAROH, math.nan)]
    with tempfile.TemporaryDirectory(prefix="kincal-talos-") as tmp:
        folder = Path(tmp)
        rows.append(("nominal model, plane fitted to the training touches",
                     *held_out(urdf, nominal_frames(folder, urdf), q_train, q_valid, names),
                     math.nan))
        rows.append(("  the same, roll and pitch in the plane's frame less their training "
                     "mean (the data README's reading)",
                     *held_out(urdf, nominal_frames(folder, urdf), q_train, q_valid, names,
                               training_mean=True), math.nan))
        train = DATA / "left_train.csv"  # kincal reads the log as it is (metadata skipped)
        variants = [("kincal defaults (placement model, lambda auto: evidence)", ())]
        if args.variants:
            variants += [("kincal, --lambda cv", ("--lambda", "cv")),
                         ("kincal, --model offsets", ("--model", "offsets")),
                         ("kincal, tilt sigma 0.02 deg", ("--orientation-sigma-deg", "0.02")),
                         ("kincal, --lambda cv (model auto judged by CV)",
                          ("--lambda", "cv", "--model", "auto")),
                         ("kincal, --compliance on the stance leg's 6 joints",
                          ("--compliance", *LEG)),
                         ("kincal, --compliance on the stance leg's roll joints",
                          ("--compliance", "leg_left_2_joint", "leg_left_6_joint")),
                         ("kincal, --compliance leg_left_5_joint (the evidence's best one)",
                          ("--compliance", "leg_left_5_joint")),
                         ("kincal, --compliance leg_left_5_joint leg_left_3_joint",
                          ("--compliance", "leg_left_5_joint", "leg_left_3_joint")),
                         ("kincal, --prior-deg 1 (the angles' prior scale given)",
                          ("--prior-deg", "1")),
                         ("kincal, --noise-mm 1 (the noise given)", ("--noise-mm", "1")),
                         ("kincal, --fix '*_joint.t?' (placement: rotations only)",
                          ("--fix", "*_joint.tx", "*_joint.ty", "*_joint.tz")),
                         ("kincal, --fix tool.rx tool.ry (face tilt held at its start)",
                          ("--fix", "tool.rx", "tool.ry")),
                         ("kincal, --robust huber", ("--robust", "huber")),
                         ("kincal, --robust cauchy", ("--robust", "cauchy"))]
        for k, (label, extra) in enumerate(variants):
            cal, frames = calibrate(folder, urdf, train, f"v{k}", *extra)
            rows.append((label, *held_out(cal, frames, q_train, q_valid, names),
                         LOG_EVIDENCE[f"v{k}"]))
            if args.loo:
                LOO[label] = leave_one_out(folder, urdf, names, q_train, extra, f"v{k}")
            if k == 0:
                rows.append(("  the same, after one tilt of the table fitted to the held-out "
                             "touches themselves (the table's turn between the days out)",
                             *held_out(cal, frames, q_train, q_valid, names, table_tilt=True),
                             math.nan))
                rows.append(("  the same, roll and pitch in the plane's frame less their "
                             "training mean (the data README's reading)",
                             *held_out(cal, frames, q_train, q_valid, names,
                                       training_mean=True), math.nan))
                rows.append(("  the same, against the calibration's own plane (FRAMES.json) "
                              "instead of the plane refitted to the training touches",
                              *held_out(cal, frames, q_train, q_valid, names, plane=""),
                              math.nan))
            if k == 0 or "--fix" in extra:
                rows.append(("  the same, the URDF's tip frame and the contact point alone "
                             "(FRAMES.json's face tilt not applied)",
                             *held_out(cal, frames, q_train, q_valid, names, face_tilt=False),
                             math.nan))
            if "--compliance" in extra:
                rows.append(("  the same, the URDF alone (FRAMES.json's compliance not applied)",
                             *held_out(cal, frames, q_train, q_valid, names, compliance=False),
                             math.nan))
                rows.append(("  the same, the URDF with the deflection at the training touches' "
                             "mean gravity torque folded into the joints",
                             *held_out(cal, frames, q_train, q_valid, names, compliance="mean"),
                             math.nan))
        if args.variants:
            # the floor: both days fitted together, the plane through every touch, judged on
            # the second day's touches in sample: what the chain model can explain at best
            both = folder / "both_days.csv"
            write_joint_csv(both, names, np.vstack([q_train, q_valid]))
            q_both = np.vstack([q_train, q_valid])
            cal, frames = calibrate(folder, urdf, both, "both")
            rows.append(("kincal defaults fitted on both days (in sample: the floor)",
                         *held_out(cal, frames, q_both, q_valid, names), math.nan))
            # the same with a plane per day (a 'plane' column): the table as the robot's
            # left sole sees it may move between the days; judged on the second day's
            # touches against the second day's plane as the calibration identified it
            days = folder / "both_days_planes.csv"
            write_joint_csv(days, names, q_both, [1] * len(q_train) + [2] * len(q_valid))
            cal, frames = calibrate(folder, urdf, days, "days")
            rows.append(("the same with a plane per day (in sample, the second day's plane)",
                         *held_out(cal, frames, q_both, q_valid, names, plane="2"), math.nan))
            rows.append(("  the first day's plane against the second's: tilt [deg], offset "
                         "[mm]", math.nan, *plane_change(frames), math.nan))
        rows += mirrored(urdf, folder)
    if LOO:
        print("Leave-one-out on the training day (RMS over the 21 touches, each predicted by "
              "the calibration on the other 20): height [mm], roll, pitch [deg]")
        for label, v in LOO.items():
            print(f"| {label} | {v[0]:.2f} | {v[1]:.3f} | {v[2]:.3f} |")
        print()
    print(f"TALOS left sole -> left gripper, flush table touches: {len(q_train)} training "
          f"(2022-10-28), {len(q_valid)} held-out (2022-11-07); held-out RMS")
    width = max(len(label) for label, *_ in rows)
    print(f"| {'model':<{width}} | height [mm] | roll [deg] | pitch [deg] | log evidence |")
    print(f"|{'-' * (width + 2)}|-------------|------------|-------------|--------------|")
    for label, h, r, p, ev in rows:
        print(f"| {label:<{width}} | " + (f"{h:11.2f}" if math.isfinite(h) else " " * 11)
              + f" | {r:10.3f} | {p:11.3f} | "
              + (f"{ev:12.1f}" if math.isfinite(ev) else " " * 12) + " |")
    for day, q in (("training", q_train), ("held-out", q_valid)):
        d50, dmax, t50, tmax = feet_closure(urdf, names, q)
        print(f"The feet, {day} touches: both legs' joint values on the nominal model put the "
              f"right sole within {d50:.3f} mm (median; max {dmax:.3f}) and {t50:.4f} deg "
              f"(max {tmax:.4f}) of one place")
    return 0


if __name__ == "__main__":
    sys.exit(main())
