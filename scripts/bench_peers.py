#!/usr/bin/env python3
"""kincal vs FIGAROH vs pybotics on the same synthetic UR10 data; prints a Markdown table.

Data (kincal.simulation, one simulated robot for every set): UR10 from example-robot-data,
chain base_link -> tool0, MD-H table with planted errors (0.3 mm / 0.03 deg SD), unknown
measurement frame, tool point (0.05, 0.02, 0.10) m off by ~2 mm from the guess.

  tracker-60    60 poses, 400 mm cube at (0.6, 0.2, 0.4) m, tilt <= 30 deg, 0.01 mm noise
  tracker-1000  1000 poses, same cube, 0.01 mm noise            (skipped with --quick)
  rtest-60      60 poses, 20 mm cube, tilt <= 15 deg, 0.05 mm noise

Held out: 300 other poses in the 400 mm cube, exact (noise-free) positions of the same
simulated robot. Every tool predicts them with its own identified model, measurement
frame and tool point; RMS and mean of the 3-D distance [mm].

Fits: kincal calibrate(method="l2") (lambda by CV) and method="ls" (time = the calibrate
call); FIGAROH full_params with its default `structural` selection and with
`excitation`; pybotics `mdh` with its own (per-pose distance) residual, capped by
max_nfev and a subprocess timeout (reported as capped / timed out). Peers run in their
venvs (.peers/, see scripts/peers/README.md) through the adapters; their time is the
adapter's fit_time_s (wall) and fit_cpu_s (process CPU).

Usage:
    /tmp/venv/bin/python scripts/bench_peers.py [--quick] [--skip-pybotics]
        [--pybotics-timeout 90] [--seed 0]
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
from pathlib import Path

import numpy as np

from kincal import calibrate, mdh
from kincal.robot import Robot
from kincal.rotations import rotx
from kincal.simulation import (Truth, cube_poses, latin_hypercube, measure, planted_table,
                               random_rotation_near, true_positions)

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT / ".peers"
ADAPTERS = ROOT / "scripts" / "peers"
CENTER = np.array([0.6, 0.2, 0.4])
TOOL = np.array([0.05, 0.02, 0.10])
# per-set pybotics budget: max_nfev (trf with a 2-point Jacobian: ~28 cost evaluations per
# nfev, ~45 us CPU per pose and evaluation -> ~75 ms per nfev at N = 60, ~1.3 s at N = 1000)
PYB_NFEV = {60: 600, 1000: 40}


def rms_mean(pred, ref):
    d = np.linalg.norm(np.asarray(pred) - np.asarray(ref), axis=1) * 1e3
    return float(np.sqrt(np.mean(d ** 2))), float(np.mean(d))


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


def run_kincal(robot, data, method, q_test, p_test):
    t0, c0 = time.perf_counter(), time.process_time()
    res = calibrate(robot, data, method=method)
    t1, c1 = time.perf_counter(), time.process_time()
    rms, mean = rms_mean(res.predict(q_test), p_test)
    n_free = sum(p.status == "identified" for p in res.parameters)
    note = f"lambda={res.lam:.3g}" if method == "l2" else ""
    return dict(tool="kincal", variant=method.upper() + (" (CV)" if method == "l2" else ""),
                n_params=n_free, rms=rms, mean=mean, wall=t1 - t0, cpu=c1 - c0,
                note=note, ok=True)


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
    base = dict(tool=peer, variant=variant, n_params=None, rms=float("nan"), mean=float("nan"),
                wall=float("nan"), cpu=float("nan"), note="", ok=False)
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
    rms, mean = rms_mean(r["p_pred"], p_test)
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
                mean=mean, wall=float(r["fit_time_s"]), cpu=float(r.get("fit_cpu_s", np.nan)),
                note="; ".join(note), ok=True)
    return base


def fmt(x, nd=3):
    if x is None:
        return "-"
    if isinstance(x, float) and not np.isfinite(x):
        return "n/a"
    return f"{x:.{nd}g}" if abs(x) < 1e-2 else f"{x:.{nd}f}" if abs(x) < 10 else f"{x:.1f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="skip the 1000-pose set and pybotics")
    ap.add_argument("--skip-pybotics", action="store_true")
    ap.add_argument("--pybotics-timeout", type=float, default=90.0,
                    help="subprocess timeout per pybotics fit [s]")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    skip_pyb = args.quick or args.skip_pybotics
    warnings.simplefilter("ignore")
    cmd_line = " ".join([sys.executable,
                         os.path.relpath(__file__, ROOT)] + (argv if argv is not None else sys.argv[1:]))
    load0 = os.getloadavg()
    t_start = time.perf_counter()

    robot = Robot.load("ur10", tip="tool0", base="base_link")
    model = mdh.extract(robot.geometry)
    rng = np.random.default_rng(args.seed)
    t = time.perf_counter()
    truth, sets = make_data(robot, model, rng, args.quick)
    t_data = time.perf_counter() - t

    common = dict(
        urdf=str(robot.source), joint_names=list(robot.joint_names),
        base_frame="base_link", tip_frame="tool0", tool_guess=TOOL.copy(),
        mdh=model.table[:, [1, 0, 3, 2]].copy(), T_base=np.asarray(model.T_base_0, float),
        T_tool=np.asarray(model.T_n_tip, float), joint_kinds=list(model.kinds))

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for s in sets:
            d, q_test, p_test = s["data"], s["q_test"], s["p_test"]
            print(f"{s['name']}: held-out max wrapped joint distance to nearest training pose "
                  f"{s['branch_dq']:.2f} rad", file=sys.stderr)
            job = dict(common, q_test=q_test, p_test=p_test,
                       q_train=np.asarray(d.joint_values), p_train=np.asarray(d.positions))
            res = []
            for method in ("l2", "ls"):
                res.append(run_kincal(robot, d, method, q_test, p_test))
                print(f"[{time.perf_counter() - t_start:6.1f} s] {s['name']} kincal {method}: "
                      f"{res[-1]['rms']:.4f} mm, {res[-1]['wall']:.2f} s", file=sys.stderr)
            for est in ("structural", "excitation"):
                res.append(run_peer("figaroh", job, {"model": "full_params", "estimation": est},
                                    q_test, p_test, tmp, f"{s['name']}-fig-{est}", 300))
                res[-1]["variant"] = f"full_params/{est}" + (" (default)" if est == "structural" else "")
                print(f"[{time.perf_counter() - t_start:6.1f} s] {s['name']} figaroh {est}: "
                      f"{res[-1]['rms']:.4f} mm, {res[-1]['wall']:.2f} s {res[-1]['note']}",
                      file=sys.stderr)
            if not skip_pyb:
                nfev = PYB_NFEV[s["n"]]
                res.append(run_peer("pybotics", job, {"variant": "mdh", "residual": "norm",
                                                      "max_nfev": nfev},
                                    q_test, p_test, tmp, f"{s['name']}-pyb", args.pybotics_timeout))
                res[-1]["variant"] = "mdh, own residual"
                print(f"[{time.perf_counter() - t_start:6.1f} s] {s['name']} pybotics: "
                      f"{res[-1]['rms']:.4f} mm, {res[-1]['wall']:.2f} s {res[-1]['note']}",
                      file=sys.stderr)
            ref = res[0]
            for r in res:
                r["set"] = f"{s['name']} (N={s['n']}, {s['size'] * 1e3:g} mm, "\
                           f"{s['noise'] * 1e3:g} mm noise)"
                r["acc_ratio"] = r["rms"] / ref["rms"] if r is not ref and r["ok"] else None
                r["speed_ratio"] = r["wall"] / ref["wall"] if r is not ref and r["ok"] else None
                r["cpu_ratio"] = r["cpu"] / ref["cpu"] if r is not ref and r["ok"] else None
            rows += res
    load1 = os.getloadavg()
    total = time.perf_counter() - t_start

    print("## kincal vs FIGAROH vs pybotics (UR10, base_link -> tool0, synthetic)\n")
    print(f"Command: `{cmd_line}`  ")
    print(f"Machine: {os.cpu_count()} CPUs; load average (1/5/15 min) at start "
          f"{load0[0]:.2f}/{load0[1]:.2f}/{load0[2]:.2f}, at end "
          f"{load1[0]:.2f}/{load1[1]:.2f}/{load1[2]:.2f}. Data generation {t_data:.1f} s, "
          f"total {total:.0f} s.  ")
    print("Held out (per set): 300 poses in the 400 mm cube (tilt <= 30 deg), in the IK branch "
          "of that set's training poses, exact positions of the same simulated robot; each "
          "tool predicts them with its own identified model, measurement frame and tool "
          "point.  ")
    print("Ratios vs kincal L2 on the same set: accuracy = peer RMS / kincal-L2 RMS (> 1: "
          "kincal more accurate); speed = peer fit wall time / kincal-L2 wall time (> 1: "
          "kincal faster); CPU likewise with process CPU time.\n")
    print("| data set | tool / variant | params | held-out RMS [mm] | held-out mean [mm] | "
          "fit wall [s] | fit CPU [s] | acc. ratio | speed ratio (wall) | speed ratio (CPU) | notes |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        print(f"| {r['set']} | {r['tool']} {r['variant']} | "
              f"{'-' if r['n_params'] is None else r['n_params']} | {fmt(r['rms'], 4)} | "
              f"{fmt(r['mean'], 4)} | {fmt(r['wall'])} | {fmt(r['cpu'])} | "
              f"{fmt(r['acc_ratio'])} | {fmt(r['speed_ratio'])} | {fmt(r['cpu_ratio'])} | "
              f"{r['note']} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
