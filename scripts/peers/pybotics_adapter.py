#!/usr/bin/env python3
"""Peer adapter: kinematic calibration with pybotics (MD-H model + scipy least squares).

Runs inside ``.peers/pybotics-venv`` (see ``setup_peers.sh``) as a subprocess worker::

    .peers/pybotics-venv/bin/python scripts/peers/pybotics_adapter.py JOB.npz OUT.npz [--meta JOB.json]

pybotics has no URDF reader: it only knows Modified DH (Craig) chains, so the job
describes the chain as an MD-H table plus two fixed transforms (see README.md for how
to make them with ``kincal.mdh.extract``).

Job: the common fields of ``adapter_io`` (q_train, p_train, q_test, p_test), plus

    mdh         (n, 4) nominal MD-H rows [alpha_{i-1} rad, a_{i-1} m, theta_offset_i rad, d_i m]
                (pybotics' own column order)
    T_base      (4, 4) pose of MD-H frame 0 in the robot base frame B (default identity)
    T_tool      (4, 4) pose of the tip frame E in MD-H frame n (default identity)
    tool_guess  (3,)   initial tool point in the tip frame E [m] (default 0)
    joint_kinds (n,)   optional "revolute" | "prismatic" (default all revolute)
    T_meas_base (4, 4) optional initial guess of B in M; default: rigid (Kabsch) fit of
                the nominal model's points to p_train
    options     JSON object (string), optional:
                  variant   "mdh" (default) | "mdh_min" | "theta" | "all"  (see chain_mask)
                  residual  "norm" (default: pybotics' optimize_accuracy, one distance per
                            posture) | "xyz" (diagnostic: 3N signed errors, same model and
                            solver, not pybotics' error function)
                  max_nfev  passed to least_squares (default: scipy's, 100 x n_params)

Output (``.npz``):

    p_pred (K, 3) predicted test positions in M [m]; p_fit (N, 3) the same for the
    training postures; fit_time_s (frame guess + least_squares, perf_counter); fit_cpu_s
    (the same span in process CPU time, robust to a busy machine);
    solver_time_s (least_squares alone); n_params; param_names; param_values (SI units,
    Euler ZYX angles for the world frame); nfev; success; status_message; rms_train_mm;
    rms_test_mm (if p_test); peer; peer_version; variant; notes (text); error (text, empty
    when it worked). Exit status 0 on success, 1 on failure (the output is still written).
"""

from __future__ import annotations

import sys
import time

import numpy as np
from adapter_io import rms_mm, worker_main

PEER = "pybotics"
PARALLEL_SIN = 1e-6  # |sin(alpha)| below which consecutive axes count as parallel


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """4x4 rigid T minimising |T src - dst|^2 (points as rows)."""
    cs, cd = src.mean(0), dst.mean(0)
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, cd - R @ cs
    return T


# ----------------------------------------------------------------------------- model
def build_robot(job: dict):
    from pybotics.kinematic_chain import MDHKinematicChain
    from pybotics.link import PrismaticMDHLink, RevoluteMDHLink
    from pybotics.robot import Robot
    from pybotics.tool import Tool

    table = np.asarray(job["mdh"], dtype=float)
    n = len(table)
    kinds = job.get("joint_kinds") or ["revolute"] * n
    if isinstance(kinds, str):
        kinds = [kinds]
    links = []
    for row, kind in zip(table, kinds):
        cls = PrismaticMDHLink if str(kind).startswith("prism") else RevoluteMDHLink
        links.append(cls(*[float(x) for x in row]))
    T_base = np.asarray(job.get("T_base", np.eye(4)), dtype=float)
    T_tool = np.asarray(job.get("T_tool", np.eye(4)), dtype=float)
    tool_guess = np.asarray(job.get("tool_guess", np.zeros(3)), dtype=float)
    # tool = tip frame placement with the tool point as its origin (orientation unused)
    tool_matrix = T_tool.copy()
    tool_matrix[:3, 3] = T_tool[:3, :3] @ tool_guess + T_tool[:3, 3]
    robot = Robot(kinematic_chain=MDHKinematicChain(links), tool=Tool(matrix=tool_matrix),
                  world_frame=T_base.copy())
    return robot, list(kinds)


def chain_mask(table: np.ndarray, kinds: list, variant: str) -> tuple[np.ndarray, list]:
    """Boolean (n, 4) mask over [alpha, a, theta, d] and the reasons for dropped entries.

    ``mdh`` (default): every MD-H parameter except the ones a free 6-DoF world frame and
    a free tool point absorb exactly: all of row 1 (alpha_0, a_0, theta_1, d_1), and
    theta_n, d_n of a last revolute joint. The d's of consecutive parallel axes stay
    free: at the nominal alpha = 0 only their sum is observable, but once alpha moves
    they let MD-H mimic a tilt of one parallel axis toward the next (a Hayati beta,
    which MD-H cannot express otherwise), at the price of large, ill-conditioned d's.
    ``mdh_min``: ``mdh`` without those d's (every d but the first of a parallel run),
    minimal at the nominal model, so beta-type errors stay unmodelled.
    ``theta``: joint offsets theta_2 .. theta_{n-1} only (pybotics' documented example
    identifies theta only). ``all``: the full 4n table, redundancies left to the solver.
    """
    n = len(table)
    mask = np.ones((n, 4), dtype=bool)
    why = []
    if variant == "all":
        return mask, why
    if variant == "theta":
        mask[:] = False
        mask[1:n - 1, 2] = True
        why.append("theta_1 absorbed by the world frame, theta_n by the tool point")
        return mask, why
    if variant not in ("mdh", "mdh_min"):
        raise ValueError(f"unknown variant {variant!r} (mdh, mdh_min, theta, all)")
    mask[0, :] = False
    why.append("row 1 (alpha_0, a_0, theta_1, d_1) absorbed by the 6-DoF world frame")
    if not str(kinds[-1]).startswith("prism"):
        mask[n - 1, 2:] = False
        why.append("theta_n, d_n absorbed by the tool point")
    if variant == "mdh_min":
        for i in range(1, n):
            if abs(np.sin(table[i, 0])) < PARALLEL_SIN and mask[i, 3]:
                mask[i, 3] = False
                why.append(f"d_{i + 1} dropped: axes {i} and {i + 1} parallel "
                           "(only the sum of their d's is observable at nominal)")
    return mask, why


# ----------------------------------------------------------------------------- run
def run(job: dict) -> dict:
    import pybotics
    import scipy
    from pybotics.geometry import matrix_2_vector
    from pybotics.optimization import OptimizationHandler, optimize_accuracy
    from scipy.optimize import least_squares

    opts = job["options"]
    variant = opts.get("variant", "mdh")
    q_train = np.asarray(job["q_train"], dtype=float)
    p_train = np.asarray(job["p_train"], dtype=float)
    q_test = np.asarray(job["q_test"], dtype=float)
    notes = []

    robot, kinds = build_robot(job)
    table = robot.kinematic_chain.matrix
    mask, why = chain_mask(table, kinds, variant)
    notes += why

    t0, c0 = time.perf_counter(), time.process_time()
    # initial measurement frame: given, or a rigid fit of the nominal points (pybotics'
    # example starts from a known world frame; an arbitrary tracker frame needs a guess)
    if job.get("T_meas_base") is not None:
        T_MB = np.asarray(job["T_meas_base"], dtype=float)
    else:
        P_B = np.array([robot.fk(q)[:3, 3] for q in q_train])  # world_frame == T_base here
        T_MB = kabsch(P_B, p_train)
    robot.world_frame = T_MB @ robot.world_frame
    handler = OptimizationHandler(robot=robot, kinematic_chain_mask=list(mask.ravel()),
                                  tool_mask=[True, True, True, False, False, False],
                                  world_mask=True)
    x0 = handler.generate_optimization_vector()
    residual = opts.get("residual", "norm")
    kw = {} if opts.get("max_nfev") is None else {"max_nfev": int(opts["max_nfev"])}
    if residual == "norm":  # pybotics' own error function (documented example)
        fun, args = optimize_accuracy, (handler, q_train, p_train)
    elif residual == "xyz":  # diagnostic, NOT pybotics': 3N signed residuals, same model
        fun, args = _xyz_residuals, (handler, q_train, p_train)
    else:
        raise ValueError(f"unknown residual {residual!r} (norm, xyz)")
    t1 = time.perf_counter()
    result = least_squares(fun=fun, x0=x0, args=args, **kw)
    t2, c2 = time.perf_counter(), time.process_time()
    # optimize_accuracy leaves the robot at the *last evaluated* vector (often a
    # finite-difference probe): put the solution back before predicting
    handler.apply_optimization_vector(result.x)
    fitted = handler.robot

    p_fit = np.array([fitted.fk(q)[:3, 3] for q in q_train])
    p_pred = np.array([fitted.fk(q)[:3, 3] for q in q_test])

    cols = ["alpha", "a", "theta", "d"]
    names = [f"{cols[c]}_{i + 1}" for i in range(len(table)) for c in range(4) if mask[i, c]]
    names += ["tool_x", "tool_y", "tool_z"]
    names += ["world_x", "world_y", "world_z", "world_ez", "world_ey", "world_ex"]
    wv = matrix_2_vector(fitted.world_frame)
    if abs(abs(wv[4]) - np.pi / 2) < 0.1:
        notes.append("world frame near the Euler ZYX singularity (pitch ~ +-90 deg)")
    if residual == "norm":
        notes.append("residual = per-posture Euclidean distance (pybotics optimize_accuracy / "
                     "compute_absolute_errors): N residuals, not 3N")
    else:
        notes.append("residual = 3N signed x/y/z errors (adapter's diagnostic option, not "
                     "pybotics' error function)")
    if not result.success:
        notes.append(f"least_squares did not converge: {result.message}")
    notes.append("solver: scipy.optimize.least_squares defaults (trf, 2-point finite-difference Jacobian)")
    out = dict(
        p_pred=p_pred, p_fit=p_fit,
        fit_time_s=t2 - t0, fit_cpu_s=c2 - c0, solver_time_s=t2 - t1,
        n_params=int(len(result.x)), param_names=names, param_values=result.x,
        nfev=int(result.nfev), njev=int(result.njev or 0), success=bool(result.success),
        status_message=str(result.message),
        rms_train_mm=rms_mm(p_fit, p_train),
        peer=PEER, peer_version=pybotics_version(pybotics),
        solver=f"scipy {scipy.__version__} least_squares", numpy_version=np.__version__,
        variant=variant, residual=residual, input_used="mdh+T_base+T_tool (no URDF)",
        notes="\n".join(notes), error="",
    )
    if job.get("p_test") is not None:
        out["rms_test_mm"] = rms_mm(p_pred, job["p_test"])
    return out


def _xyz_residuals(x, handler, qs, positions):
    handler.apply_optimization_vector(x)
    robot = handler.robot
    return np.concatenate([robot.fk(q)[:3, 3] - p for q, p in zip(qs, positions)])


def pybotics_version(mod) -> str:
    try:
        from importlib.metadata import version
        return version("pybotics")
    except Exception:  # pragma: no cover
        return getattr(mod, "__version__", "unknown")


def main(argv=None) -> int:
    return worker_main(PEER, run, __doc__.splitlines()[0], argv)


if __name__ == "__main__":
    sys.exit(main())
