#!/usr/bin/env python3
"""kincal vs FIGAROH vs pybotics on the same data (synthetic UR10, real TIAGo); Markdown tables.

Part 1, synthetic UR10 (skipped with --tiago-only).

Data (kincal.simulation, one simulated robot for every set): UR10 from example-robot-data,
chain base_link -> tool0, MD-H table with planted errors (0.3 mm / 0.03 deg SD), unknown
measurement frame, tool point (0.05, 0.02, 0.10) m off by ~2 mm from the guess.

  tracker-60    60 poses, 400 mm cube at (0.6, 0.2, 0.4) m, tilt <= 30 deg, 0.01 mm noise
  tracker-1000  1000 poses, same cube, 0.01 mm noise            (skipped with --quick)
  rtest-60      60 poses, 20 mm cube, tilt <= 15 deg, 0.05 mm noise

Held out: 300 other poses in the 400 mm cube, exact (noise-free) positions of the same
simulated robot. Every tool predicts them with its own identified model, measurement
frame and tool point; RMS and mean of the 3-D distance [mm].

Seeds (--seeds, default 0-4): each draws its own robot errors, poses and noise. At noise
level the tools differ by a few per cent either way from one draw to the next, so one
seed does not rank them; the first table aggregates over the seeds (geometric mean,
min and max of the ratios, and in how many runs kincal L2 was at least as accurate), the
second lists every run.

Fits: kincal calibrate(method="l2") (lambda by CV) and method="ls" (time = the calibrate
call); FIGAROH full_params with its default `structural` selection, with `excitation`
and, on the 60-pose sets, with `map_cv` (zero-mean priors on the joint parameters, their
scale by 5-fold CV: FIGAROH's counterpart of kincal's L2 + CV; about 7 s of CPU a fit at
60 poses, several minutes at 1000, hence not run there, nor with --quick); pybotics `mdh` with its own (per-pose distance) residual, capped by
max_nfev and a subprocess timeout (reported as capped / timed out). Peers run in their
venvs (.peers/, see scripts/peers/README.md) through the adapters; their time is the
adapter's fit_time_s (wall) and fit_cpu_s (process CPU).

Part 2, TIAGo arm on real motion-capture data (skipped with --skip-tiago, or with a
message when the data are absent): ../shared/data/tiago_mocap (ROOT.parent / "shared",
or --shared DIR; read in place, never copied; see its README). Chain URDF root
(base_footprint) -> wrist_ft_tool_link, joints torso_lift_joint (prismatic, m) and
arm_1..arm_7 (rad), other joints at neutral; measured point marker 1 (x1, y1, z1) in the
mocap frame, an unknown rigid transform of the root.

Protocol: every fit sees the training day (2021-11-30, 37 postures) only; the held-out day
(2021-11-26, 62 postures) is predicted with the kinematics AND the mocap frame and marker
point identified on the training day (same mocap frame both days). Reported: held-out
RMS / mean / max of the 3-D distance, training RMS (all training postures), number of
identified parameters, fit wall and CPU time, ratios to kincal-L2.

Rows: kincal through its API, time = the calibrate call: "l2" (full MD-H, lambda by CV),
"ls" (full MD-H) and "ls" with every kinematic parameter fixed except theta of the
revolute joints and d of the prismatic one (joint offsets + frames: FIGAROH's joint_offset
model), and "l2" with a backlash term on arm_6_joint (kincal.backlash; approach
directions from the t_start_robot column). FIGAROH 1.0.2 through the adapter with its own TIAGo setup (figaroh-examples
heldout_protocol.py / tiago_unified_config.yaml): unknown base and tip frames, default
`structural` estimation, outlier threshold 0.05 m, log-map position residuals;
`joint_offset` and `full_params`. Its results are checked against FIGAROH's published
numbers on the same files (data README), and FIGAROH joint_offset against kincal's offsets
row (same model: the held-out predictions should agree to a small fraction of a mm).

Usage:
    /tmp/venv/bin/python scripts/bench_peers.py [--quick] [--skip-pybotics]
        [--pybotics-timeout 90] [--seeds 0 1 2 3 4] [--tiago-only | --skip-tiago]
        [--shared DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import tiago_files  # scripts/tiago_files.py, next to this script

from kincal import CalibrationOptions, KincalWarning, Measurements, calibrate
from kincal.models import mdh
from kincal.planning.simulation import (
    Truth,
    cube_poses,
    latin_hypercube,
    measure,
    planted_table,
    random_rotation_near,
    true_positions,
)
from kincal.robot import Robot
from kincal.rotations import rotx

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT / ".peers"
ADAPTERS = ROOT / "scripts" / "peers"
CENTER = np.array([0.6, 0.2, 0.4])
TOOL = np.array([0.05, 0.02, 0.10])
# per-set pybotics budget: max_nfev (trf with a 2-point Jacobian: ~28 cost evaluations per
# nfev, ~45 us CPU per pose and evaluation -> ~75 ms per nfev at N = 60, ~1.3 s at N = 1000)
PYB_NFEV = {60: 600, 1000: 40}

TIAGO_MARKER = ("x1", "y1", "z1")
# FIGAROH's TIAGo config (figaroh-examples tiago_unified_config.yaml): outlier_threshold
FIGAROH_TIAGO_OUTLIER = 0.05
# FIGAROH 1.0.2 on exactly these files, marker 1 (published reference, data README) [mm]:
# model -> (parameters, training RMS, held-out RMS, mean, max)
FIGAROH_PUBLISHED = {"joint_offset": (14, 2.88, 4.23, 3.85, 11.95),
                     "full_params": (30, 1.68, 3.22, 2.67, 12.23)}


def error_stats(pred, ref):
    """RMS, mean and max of the 3-D distance [mm]."""
    d = np.linalg.norm(np.asarray(pred) - np.asarray(ref), axis=1) * 1e3
    return float(np.sqrt(np.mean(d ** 2))), float(np.mean(d)), float(np.max(d))


def heldout_poses(robot, q_train, n, rng):
    """(n, dof) poses at n points of the 400 mm cube (tilt <= 30 deg) in the IK branch of
    ``q_train``: each IK starts from the training pose whose nominal tool point is nearest,
    so the held-out set tests the cube, not another arm configuration."""
    T = robot.tip_poses(q_train)
    p_nom = np.einsum("nij,j->ni", T[:, :3, :3], TOOL) + T[:, :3, 3]
    pts = CENTER + latin_hypercube(2 * n, rng) * 0.4 - 0.2  # spare points for IK failures
    out = []
    for p in pts:
        for seed in np.argsort(np.linalg.norm(p_nom - p, axis=1))[:20]:
            q, ok = robot.inverse_kinematics(
                p, TOOL, random_rotation_near(rotx(np.pi), np.radians(30), rng),
                start=q_train[seed], max_iterations=100)
            if ok:
                out.append(q)
                break
        if len(out) == n:
            break
    if len(out) < n:
        raise RuntimeError(f"only {len(out)} held-out poses found in the training IK branch")
    out = np.array(out)
    # branch check: wrapped joint distance to the nearest training pose [rad]
    dq = np.angle(np.exp(1j * (out[:, None, :] - q_train[None, :, :])))
    return out, float(np.max(np.min(np.abs(dq).max(axis=2), axis=1)))


def make_data(robot, model, rng, quick):
    truth = Truth(planted_table(model, rng), np.array([1.2, -0.4, 0.3, 0.3, -0.5, 2.0]),
                  TOOL + np.array([0.0015, -0.001, 0.0012]))
    sets = [("tracker-60", 60, 0.4, 30, 1e-5)]
    if not quick:
        sets.append(("tracker-1000", 1000, 0.4, 30, 1e-5))
    sets.append(("rtest-60", 60, 0.02, 15, 5e-5))
    out = []
    for name, n, size, tilt, noise in sets:
        q = cube_poses(robot, n, CENTER, size, TOOL, rng, max_tilt=np.radians(tilt))
        q_test, dmax = heldout_poses(robot, q, 300, rng)
        out.append(dict(name=name, n=n, size=size, noise=noise, q_test=q_test,
                        p_test=true_positions(model, truth, q_test), branch_dq=dmax,
                        data=measure(model, truth, q, noise, rng)))
    return truth, out


def run_kincal(robot, data, options, variant, q_test, p_test, approach_test=None):
    """One kincal calibrate call (timed) and its predictions of the held-out poses.

    approach_test: approach directions of the held-out poses (for backlash terms)."""
    t0, c0 = time.perf_counter(), time.process_time()
    res = calibrate(robot, data, options)
    t1, c1 = time.perf_counter(), time.process_time()
    pred = res.predict(q_test, approach_test)
    rms, mean, mx = error_stats(pred, p_test)
    n_free = sum(p.status == "identified" for p in res.parameters)
    return dict(tool="kincal", variant=variant, n_params=n_free, rms=rms, mean=mean, max=mx,
                train_rms=error_stats(res.predict(data.joint_values, data.approach),
                                      data.positions)[0],
                wall=t1 - t0, cpu=c1 - c0, pred=pred,
                note=f"lambda={res.lam:.3g}" if options.method == "l2" else "", ok=True)


def run_peer(peer, job, options, q_test, p_test, tmp, tag, timeout):
    job = dict(job, options=json.dumps(options))
    arrays = {k: v for k, v in job.items() if isinstance(v, np.ndarray)}
    meta = {k: v for k, v in job.items() if not isinstance(v, np.ndarray)}
    jp, mp, op = (os.path.join(tmp, f"{tag}.{e}") for e in ("npz", "json", "out.npz"))
    np.savez(jp, **arrays)
    with open(mp, "w", encoding="utf-8") as f:
        json.dump(meta, f)
    py = PEERS / f"{peer}-venv" / "bin" / "python"
    cmd = [str(py), str(ADAPTERS / f"{peer}_adapter.py"), jp, op, "--meta", mp]
    variant = options.get("estimation", options.get("variant", ""))
    nan = float("nan")
    base = dict(tool=peer, variant=variant, n_params=None, rms=nan, mean=nan, max=nan,
                train_rms=nan, wall=nan, cpu=nan, pred=None, note="", ok=False)
    if not py.exists():
        base["note"] = f"{py.relative_to(ROOT)} missing: run bash scripts/peers/setup_peers.sh"
        return base
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        base.update(wall=time.perf_counter() - t0,
                    note=f"TIMED OUT after {timeout:.0f} s (subprocess killed; no result)")
        return base
    if not os.path.exists(op):
        base["note"] = f"adapter failed (rc {proc.returncode}): {proc.stderr.strip()[-300:]}"
        return base
    with np.load(op, allow_pickle=False) as z:
        r = {k: z[k] for k in z.files}
    err = str(r.get("error", ""))
    if err:
        base["note"] = f"adapter error: {err[:200]}"
        return base
    rms, mean, mx = error_stats(r["p_pred"], p_test)
    note = []
    if peer == "pybotics":
        nfev = int(r.get("nfev", -1))
        if options.get("max_nfev") and nfev >= int(options["max_nfev"]):
            note.append(f"CAPPED at max_nfev={options['max_nfev']} (not converged)")
        else:
            note.append(f"nfev={nfev}")
    if "n_outliers" in r and int(r["n_outliers"]):
        note.append(f"{int(r['n_outliers'])} outliers removed")
    base.update(variant=str(r.get("variant", variant)), n_params=int(r["n_params"]), rms=rms,
                mean=mean, max=mx, train_rms=error_stats(r["p_fit"], job["p_train"])[0],
                wall=float(r["fit_time_s"]), cpu=float(r.get("fit_cpu_s", np.nan)),
                pred=r["p_pred"], note="; ".join(note), ok=True)
    return base


def fmt(x, nd=3):
    if x is None:
        return "-"
    if isinstance(x, float) and not np.isfinite(x):
        return "n/a"
    return f"{x:.{nd}g}" if abs(x) < 1e-2 else f"{x:.{nd}f}" if abs(x) < 10 else f"{x:.1f}"


def fmt_mm(x):
    """Millimetres with three decimals (the TIAGo errors span 1-20 mm)."""
    return "n/a" if not np.isfinite(x) else f"{x:.3f}"


def set_ratios(res, label):
    """Label the rows of one data set and set their ratios to its first row (kincal L2)."""
    ref = res[0]
    for r in res:
        r["set"] = label
        other = r is not ref and r["ok"]
        r["acc_ratio"] = r["rms"] / ref["rms"] if other else None
        r["speed_ratio"] = r["wall"] / ref["wall"] if other else None
        r["cpu_ratio"] = r["cpu"] / ref["cpu"] if other else None


def machine_line(load0, load1, extra):
    return (f"Machine: {os.cpu_count()} CPUs; load average (1/5/15 min) at start "
            f"{load0[0]:.2f}/{load0[1]:.2f}/{load0[2]:.2f}, at end "
            f"{load1[0]:.2f}/{load1[1]:.2f}/{load1[2]:.2f}. {extra}  ")


def synthetic_seed(robot, model, seed, quick, skip_pyb, pyb_timeout, t_start, tmp):
    """The rows of every UR10 set for one seed (data, robot errors and noise)."""
    rng = np.random.default_rng(seed)
    _, sets = make_data(robot, model, rng, quick)
    common = dict(
        urdf=str(robot.source), joint_names=list(robot.joint_names),
        base_frame="base_link", tip_frame="tool0", tool_guess=TOOL.copy(),
        mdh=model.table[:, [1, 0, 3, 2]].copy(), T_base=np.asarray(model.T_base_0, float),
        T_tool=np.asarray(model.T_n_tip, float), joint_kinds=list(model.kinds))
    rows = []
    for s in sets:
        d, q_test, p_test = s["data"], s["q_test"], s["p_test"]
        tag = f"seed {seed} {s['name']}"
        print(f"{tag}: held-out max wrapped joint distance to nearest training pose "
              f"{s['branch_dq']:.2f} rad", file=sys.stderr)
        job = dict(common, q_test=q_test, p_test=p_test,
                   q_train=np.asarray(d.joint_values), p_train=np.asarray(d.positions))
        res = []
        for method in ("l2", "ls"):
            variant = method.upper() + (" (CV)" if method == "l2" else "")
            res.append(run_kincal(robot, d, CalibrationOptions(model="mdh", method=method, lam="cv"), variant,
                                  q_test, p_test))
            print(f"[{time.perf_counter() - t_start:6.1f} s] {tag} kincal {method}: "
                  f"{res[-1]['rms']:.4f} mm, {res[-1]['wall']:.2f} s", file=sys.stderr)
        # map_cv: FIGAROH's regularised fit (priors, scale by CV), the counterpart of
        # kincal L2 + CV; it refits per fold and candidate scale, too slow at 1000 poses
        ests = ("structural", "excitation") + (("map_cv",) if s["n"] <= 60 and not quick else ())
        for est in ests:
            res.append(run_peer("figaroh", job, {"model": "full_params", "estimation": est},
                                q_test, p_test, tmp, f"s{seed}-{s['name']}-fig-{est}", 300))
            res[-1]["variant"] = f"full_params/{est}" + (" (default)" if est == "structural" else "")
            print(f"[{time.perf_counter() - t_start:6.1f} s] {tag} figaroh {est}: "
                  f"{res[-1]['rms']:.4f} mm, {res[-1]['wall']:.2f} s {res[-1]['note']}",
                  file=sys.stderr)
        if not skip_pyb:
            nfev = PYB_NFEV[s["n"]]
            res.append(run_peer("pybotics", job, {"variant": "mdh", "residual": "norm",
                                                  "max_nfev": nfev},
                                q_test, p_test, tmp, f"s{seed}-{s['name']}-pyb", pyb_timeout))
            res[-1]["variant"] = "mdh, own residual"
            print(f"[{time.perf_counter() - t_start:6.1f} s] {tag} pybotics: "
                  f"{res[-1]['rms']:.4f} mm, {res[-1]['wall']:.2f} s {res[-1]['note']}",
                  file=sys.stderr)
        set_ratios(res, f"{s['name']} (N={s['n']}, {s['size'] * 1e3:g} mm, "
                        f"{s['noise'] * 1e3:g} mm noise)")
        one_fit = res[1]["wall"]  # kincal LS: one solve, as each peer fit is but map_cv
        for r in res:
            r["seed"] = seed
            single = r["tool"] != "kincal" and "map_cv" not in r["variant"]  # map_cv: a CV
            r["fit_ratio"] = r["wall"] / one_fit if r["ok"] and single else None
        rows += res
    return rows


def summary_rows(rows):
    """Per data set and tool/variant, over the seeds: the aggregate table's rows."""
    out = []
    keys = list(dict.fromkeys((r["set"], f"{r['tool']} {r['variant']}") for r in rows))
    for key in keys:
        rs = [r for r in rows if (r["set"], f"{r['tool']} {r['variant']}") == key]
        ok = [r for r in rs if r["ok"]]
        acc = [r["acc_ratio"] for r in ok if r["acc_ratio"] is not None]
        speed = [r["speed_ratio"] for r in ok if r["speed_ratio"] is not None]
        per_fit = [r["fit_ratio"] for r in ok if r["fit_ratio"] is not None]
        # how many of the runs each caveat concerns (a mean over capped and converged
        # runs is not a capped figure)
        flagged = Counter(r["note"].split(" (")[0] for r in rs if "CAPPED" in r["note"]
                          or "TIMED OUT" in r["note"] or not r["ok"])
        notes = [f"{k} in {v} of {len(rs)} runs" for k, v in sorted(flagged.items())]
        out.append(dict(
            set=key[0], tool=key[1], n=len(rs), n_ok=len(ok),
            rms=float(np.mean([r["rms"] for r in ok])) if ok else float("nan"),
            wall=float(np.median([r["wall"] for r in ok])) if ok else float("nan"),
            acc=acc, speed=speed, per_fit=per_fit,
            kincal_wins=sum(a >= 1.0 for a in acc), notes="; ".join(notes)))
    return out


def synthetic(args, cmd_line):
    """Part 1: the UR10 sets through kincal, FIGAROH and pybotics, over the seeds."""
    skip_pyb = args.quick or args.skip_pybotics
    load0 = os.getloadavg()
    t_start = time.perf_counter()
    robot = Robot.load("ur10", tip="tool0", base="base_link")
    model = mdh.extract(robot.geometry)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            rows += synthetic_seed(robot, model, seed, args.quick, skip_pyb,
                                   args.pybotics_timeout, t_start, tmp)
    load1 = os.getloadavg()
    total = time.perf_counter() - t_start
    seeds = ", ".join(map(str, args.seeds))

    print("## kincal vs FIGAROH vs pybotics (UR10, base_link -> tool0, synthetic)\n")
    print(f"Command: `{cmd_line}`  ")
    print(machine_line(load0, load1, f"Seeds {seeds}; total {total:.0f} s."))
    print("Each seed draws its own robot errors, poses and noise. Held out (per set and "
          "seed): 300 poses in the 400 mm cube (tilt <= 30 deg), in the IK branch of that "
          "set's training poses, exact positions of the same simulated robot; each tool "
          "predicts them with its own identified model, measurement frame and tool point.  ")
    print("Ratios vs kincal L2 on the same set and seed: accuracy = peer RMS / kincal-L2 RMS "
          "(> 1: kincal more accurate); speed = peer fit wall time / kincal-L2 wall time "
          "(> 1: kincal faster; kincal L2 runs its whole cross-validation, 251 fits); CPU "
          "likewise with process CPU time. Per fit: peer fit wall time / one kincal fit (LS) "
          "on the same data (not for FIGAROH map_cv, a cross-validation like kincal L2's).  ")
    print("Timed spans: kincal the calibrate call (setup, Jacobians, parameter selection, "
          "solve, covariance); FIGAROH create_param_list + solve_optimisation (its parameter "
          "selection, closed-form frame guess, LM with outlier refits), not its imports, "
          "config and CSV reading or report; pybotics its frame guess + least_squares. Each "
          "peer runs in its own process, its timed span after its imports and model "
          "loading.\n")
    print(f"### Over the seeds ({seeds})\n")
    print("| data set | tool / variant | runs | mean held-out RMS [mm] | acc. ratio: geometric "
          "mean (min - max) | kincal L2 at least as accurate | median fit wall [s] | "
          "speed ratio vs kincal L2 + CV | speed ratio vs one kincal fit (LS) | notes |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    gm = lambda v: float(np.exp(np.mean(np.log(v))))  # noqa: E731
    for a in summary_rows(rows):
        def spread(v):
            return f"{fmt(gm(v))} ({fmt(min(v))} - {fmt(max(v))})" if v else "-"

        acc, spd, fit = spread(a["acc"]), spread(a["speed"]), spread(a["per_fit"])
        wins = f"{a['kincal_wins']} of {len(a['acc'])}" if a["acc"] else "-"
        runs = f"{a['n_ok']}" + (f" of {a['n']}" if a["n_ok"] < a["n"] else "")
        print(f"| {a['set']} | {a['tool']} | {runs} | {fmt(a['rms'], 4)} | {acc} | {wins} | "
              f"{fmt(a['wall'])} | {spd} | {fit} | {a['notes']} |")
    print("\n### Every run\n")
    print("| seed | data set | tool / variant | params | held-out RMS [mm] | held-out mean [mm] | "
          "fit wall [s] | fit CPU [s] | acc. ratio | speed ratio (wall) | speed ratio (CPU) | notes |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['seed']} | {r['set']} | {r['tool']} {r['variant']} | "
              f"{'-' if r['n_params'] is None else r['n_params']} | {fmt(r['rms'], 4)} | "
              f"{fmt(r['mean'], 4)} | {fmt(r['wall'])} | {fmt(r['cpu'])} | "
              f"{fmt(r['acc_ratio'])} | {fmt(r['speed_ratio'])} | {fmt(r['cpu_ratio'])} | "
              f"{r['note']} |")


def published_check(row, model):
    """One line: a FIGAROH row against FIGAROH's published numbers on the same files."""
    pub = FIGAROH_PUBLISHED[model]
    head = (f"- FIGAROH `{model}`: published {pub[0]} parameters, training RMS {pub[1]:.2f}, "
            f"held-out RMS / mean / max {pub[2]:.2f} / {pub[3]:.2f} / {pub[4]:.2f} mm; ")
    if not row["ok"]:
        return head + f"this run FAILED ({row['note']})."
    got = (row["n_params"], row["train_rms"], row["rms"], row["mean"], row["max"])
    same = got[0] == pub[0] and all(round(g, 2) == p for g, p in zip(got[1:], pub[1:]))
    return head + (f"this run {got[0]}, {got[1]:.3f}, {got[2]:.3f} / {got[3]:.3f} / "
                   f"{got[4]:.3f} mm: " + ("MATCHES (to the published two decimals)." if same
                                           else "DIFFERS from the published numbers."))


def tiago(args, cmd_line):
    """Part 2: the TIAGo mocap files through kincal and FIGAROH; prints the table."""
    d, missing = tiago_files.locate(args.shared)
    if missing:
        what = "not found" if not d.is_dir() else f"lacks {', '.join(missing)}"
        print(f"## TIAGo part skipped: {d} {what} (the shared data are read in place, never "
              "copied; --shared DIR names another shared folder)")
        return
    load0 = os.getloadavg()
    t_start = time.perf_counter()
    robot = Robot.load(d / tiago_files.URDF, tip=tiago_files.TIP)
    kinds = list(zip(robot.joint_names, robot.geometry.kinds))
    prismatic = [j for j, k in kinds if k == "prismatic"]
    train, held = (Measurements.from_csv(d / f, robot.joint_names, prismatic=prismatic,
                                         position_columns=TIAGO_MARKER,
                                         order_column=tiago_files.ORDER_COLUMN)
                   for f in (tiago_files.TRAIN, tiago_files.HELD_OUT))
    q_test, p_test = np.asarray(held.joint_values), np.asarray(held.positions)
    # joint offsets + frames: everything kinematic fixed but theta (revolute) / d (prismatic)
    offsets_fix = tuple(f"{j}.{f}" for j, k in kinds for f in ("a", "alpha", "d", "theta")
                        if f != ("d" if k == "prismatic" else "theta"))
    fits = (("L2 (CV), full MD-H", CalibrationOptions(model="mdh", method="l2", lam="cv")),
            ("LS, full MD-H", CalibrationOptions(model="mdh", method="ls")),
            ("LS, joint offsets + frames", CalibrationOptions(model="mdh", method="ls", fix=offsets_fix)),
            ("L2 (CV), full MD-H + backlash arm_6",
             CalibrationOptions(model="mdh", method="l2", lam="cv", backlash=("arm_6_joint",))))
    res = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", KincalWarning)
        for variant, options in fits:
            res.append(run_kincal(robot, train, options, variant, q_test, p_test,
                                  held.approach))
            print(f"[{time.perf_counter() - t_start:6.1f} s] TIAGo kincal {variant}: "
                  f"{res[-1]['rms']:.3f} mm, {res[-1]['wall']:.2f} s", file=sys.stderr)
    kincal_warnings = sorted({str(w.message) for w in caught})

    job = dict(urdf=str(d / tiago_files.URDF), joint_names=list(robot.joint_names),
               base_frame=robot.base, tip_frame=tiago_files.TIP,
               q_train=np.asarray(train.joint_values), p_train=np.asarray(train.positions),
               q_test=q_test, p_test=p_test)
    with tempfile.TemporaryDirectory() as tmp:
        for model in ("full_params", "joint_offset"):
            res.append(run_peer("figaroh", job, {"model": model, "estimation": "structural",
                                                 "outlier_threshold": FIGAROH_TIAGO_OUTLIER},
                                q_test, p_test, tmp, f"tiago-fig-{model}", 300))
            res[-1]["variant"] = f"{model}/structural (default)"
            print(f"[{time.perf_counter() - t_start:6.1f} s] TIAGo figaroh {model}: "
                  f"{res[-1]['rms']:.3f} mm, {res[-1]['wall']:.2f} s {res[-1]['note']}",
                  file=sys.stderr)
    train_day, held_day = (f.split("_")[1]
                           for f in (tiago_files.TRAIN, tiago_files.HELD_OUT))
    set_ratios(res, f"TIAGo mocap (train {train_day} N={len(train.joint_values)}, "
                    f"held-out {held_day} N={len(q_test)})")
    kc_off, kc_backlash, fig_full, fig_off = res[2], res[3], res[4], res[5]
    load1 = os.getloadavg()
    total = time.perf_counter() - t_start

    print("## kincal vs FIGAROH on real data (TIAGo arm, motion capture)\n")
    print(f"Command: `{cmd_line}`  ")
    print(machine_line(load0, load1, f"TIAGo part {total:.0f} s."))
    print(f"Data: {d} ({tiago_files.TRAIN} for training, {tiago_files.HELD_OUT} held out). "
          f"Chain {robot.base} -> {tiago_files.TIP} ({', '.join(robot.joint_names)}; other joints at "
          "neutral); measured point: marker 1 (x1, y1, z1).  ")
    print("Fit on the training day only; the held-out day is predicted with the kinematics, "
          "mocap frame and marker point identified on the training day. Training RMS over "
          "all training postures. FIGAROH: its TIAGo setup (unknown base and tip frames, "
          f"default structural estimation, outlier threshold {FIGAROH_TIAGO_OUTLIER:g} m).  ")
    print("Ratios vs kincal L2: accuracy = held-out RMS / kincal-L2 held-out RMS (> 1: kincal "
          "L2 more accurate); speed = fit wall (CPU) time / kincal-L2 fit wall (CPU) time "
          "(> 1: kincal L2 faster).\n")
    print("| data set | tool / variant | params | held-out RMS [mm] | held-out mean [mm] | "
          "held-out max [mm] | training RMS [mm] | fit wall [s] | fit CPU [s] | acc. ratio | "
          "speed ratio (wall) | speed ratio (CPU) | notes |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in res:
        print(f"| {r['set']} | {r['tool']} {r['variant']} | "
              f"{'-' if r['n_params'] is None else r['n_params']} | {fmt_mm(r['rms'])} | "
              f"{fmt_mm(r['mean'])} | {fmt_mm(r['max'])} | {fmt_mm(r['train_rms'])} | "
              f"{fmt(r['wall'])} | {fmt(r['cpu'])} | {fmt(r['acc_ratio'])} | "
              f"{fmt(r['speed_ratio'])} | {fmt(r['cpu_ratio'])} | {r['note']} |")
    print("\nFIGAROH against its published numbers on these files (FIGAROH 1.0.2, data README):\n")
    print(published_check(fig_off, "joint_offset"))
    print(published_check(fig_full, "full_params"))
    if fig_off["ok"]:
        gap = float(np.max(np.linalg.norm(fig_off["pred"] - kc_off["pred"], axis=1)) * 1e3)
        print(f"\nSame model, two tools (FIGAROH joint_offset vs kincal LS joint offsets + "
              f"frames): held-out RMS {fig_off['rms']:.4f} vs {kc_off['rms']:.4f} mm (ratio "
              f"{fig_off['rms'] / kc_off['rms']:.4f}), training RMS {fig_off['train_rms']:.4f} "
              f"vs {kc_off['train_rms']:.4f} mm, {fig_off['n_params']} vs {kc_off['n_params']} "
              f"parameters; largest distance between their held-out predictions {gap:.2g} mm; "
              f"fit wall {fig_off['wall']:.3f} vs {kc_off['wall']:.3f} s (ratio "
              f"{fig_off['wall'] / kc_off['wall']:.1f}).")
    if fig_full["ok"]:
        print(f"\nkincal L2 + backlash arm_6 vs FIGAROH's best (full_params): held-out RMS "
              f"{kc_backlash['rms']:.3f} vs {fig_full['rms']:.3f} mm (FIGAROH / kincal "
              f"{fig_full['rms'] / kc_backlash['rms']:.2f}), max {kc_backlash['max']:.2f} vs "
              f"{fig_full['max']:.2f} mm, {kc_backlash['n_params']} vs {fig_full['n_params']} "
              f"identified parameters; fit wall {kc_backlash['wall']:.2f} vs "
              f"{fig_full['wall']:.2f} s.")
    for w in kincal_warnings:
        print(f"\nkincal warning: {w}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="skip the 1000-pose set, pybotics and FIGAROH's map_cv")
    ap.add_argument("--skip-pybotics", action="store_true")
    ap.add_argument("--pybotics-timeout", type=float, default=90.0,
                    help="subprocess timeout per pybotics fit [s]")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4],
                    help="seeds of the synthetic part (robot errors, poses, noise)")
    part = ap.add_mutually_exclusive_group()
    part.add_argument("--tiago-only", action="store_true", help="only the TIAGo part")
    part.add_argument("--skip-tiago", action="store_true", help="only the synthetic part")
    ap.add_argument("--shared", metavar="DIR",
                    help="shared folder holding data/tiago_mocap "
                         f"(default {tiago_files.DEFAULT_SHARED})")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    cmd_line = " ".join([sys.executable,
                         os.path.relpath(__file__, ROOT)] + (argv if argv is not None else sys.argv[1:]))
    if not args.tiago_only:
        synthetic(args, cmd_line)
    if not args.skip_tiago:
        if not args.tiago_only:
            print()
        tiago(args, cmd_line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
