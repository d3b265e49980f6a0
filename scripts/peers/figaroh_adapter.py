#!/usr/bin/env python3
"""Peer adapter: kinematic calibration with FIGAROH (Pinocchio, URDF, Levenberg-Marquardt).

Runs inside ``.peers/figaroh-venv`` (see ``setup_peers.sh``) as a subprocess worker::

    .peers/figaroh-venv/bin/python scripts/peers/figaroh_adapter.py JOB.npz OUT.npz [--meta JOB.json]

It follows FIGAROH's documented workflow (``BaseCalibration`` subclass with a
robot-specific ``cost_function``, unified YAML config, measurements in a CSV, unknown
base and tip frames, ``initialize()`` then ``solve()``), with the config and the CSV
written to a temporary directory from the job.

Job: the common fields of ``adapter_io`` (q_train, p_train, q_test, p_test), plus

    urdf        path of the URDF (meshes are not loaded)
    joint_names (n,)   the chain joints, root first (FIGAROH's active_joints)
    base_frame  name of the base frame B (a URDF link or joint frame)
    tip_frame   name of the tip frame E
    tool_guess  (3,)   tool point in E [m]; FIGAROH starts from its own closed-form
                frame guess, so this is only used if that guess is unavailable
    options     JSON object (string), optional:
                  model      "full_params" (default: 6 placement errors per joint, then
                             QR base parameters) | "joint_offset" (one offset per joint)
                  estimation "structural" (default) | "excitation" | "map" | "map_cv" |
                             "cv_subset"   (FIGAROH's estimation.method)
                  outlier_threshold  [m], default 0.02 as in FIGAROH's UR10 example
                  max_iterations     outlier-removal refits, default 3 (solve() default)

Output (``.npz``): p_pred (K, 3) predicted test positions in M [m]; p_fit (N, 3) for the
training postures; fit_time_s (parameter selection + solve_optimisation, perf_counter);
fit_cpu_s (the same span in process CPU time, robust to a busy machine);
select_time_s; solver_time_s (solve_optimisation: closed-form frame guess + LM with
outlier removal); solve_total_s (solve() with FIGAROH's own evaluation/report);
n_params; param_names; param_values [m, rad]; n_outliers; nfev; success; rms_train_mm;
rms_test_mm (if p_test); peer; peer_version; variant; notes; error (empty when it
worked). Exit status 0 on success, 1 on failure (the output is still written).
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
import time
import warnings

import numpy as np
from adapter_io import rms_mm, worker_main

PEER = "figaroh"


# ----------------------------------------------------------------------------- config
def write_config(path: str, job: dict, csv_path: str, n_samples: int, model_name: str) -> dict:
    """A FIGAROH 1.x unified config (``robot`` + ``tasks.calibration``) for a 3-D point."""
    import yaml

    opts = job["options"]
    joints = list(job["joint_names"])
    cfg = {
        "robot": {
            "name": model_name,
            "properties": {"joints": {"active_joints": joints}},
        },
        "tasks": {
            "calibration": {
                "enabled": True,
                "parameters": {
                    "calibration_level": opts.get("model", "full_params"),
                    "include_non_geometric": False,
                    "outlier_threshold": float(opts.get("outlier_threshold", 0.02)),
                    "estimation": {"method": opts.get("estimation", "structural")},
                },
                "kinematics": {
                    "base_frame": job["base_frame"],
                    "tool_frame": job["tip_frame"],
                },
                "measurements": {
                    "markers": [{
                        "name": "tool_point",
                        "reference_joint": joints[-1],
                        "measurable_dof": [True, True, True, False, False, False],
                    }],
                    "poses": {"base_pose": [0.0] * 6, "tool_pose": [0.0] * 6},
                },
                "data": {
                    "source_file": csv_path,
                    "validation_data_file": "",
                    "sample_configurations_file": "",
                    "number_of_samples": int(n_samples),
                },
            }
        },
    }
    with open(path, "w", encoding="utf-8") as f:
        yaml.safe_dump(cfg, f, sort_keys=False)
    return cfg


def write_csv(path: str, joints, q: np.ndarray, p: np.ndarray) -> None:
    """FIGAROH's measurement CSV: x1, y1, z1 and one column per active joint."""
    header = ["x1", "y1", "z1"] + list(joints)
    rows = np.hstack([p, q])
    np.savetxt(path, rows, delimiter=",", header=",".join(header), comments="", fmt="%.17g")


# ----------------------------------------------------------------------------- run
def run(job: dict) -> dict:
    import pinocchio as pin
    from figaroh.calibration.base_calibration import BaseCalibration
    from figaroh.calibration.calibration_tools import calc_updated_fkm
    from pinocchio.robot_wrapper import RobotWrapper

    class PeerCalibration(BaseCalibration):
        """Cost as in FIGAROH's UR10 example: SE3 log-map residuals, unit weights."""

        def cost_function(self, var):
            PEEe = calc_updated_fkm(self.model, self.data, var, self.q_measured,
                                    self.calib_config)
            raw = self._compute_logmap_residuals(self.PEE_measured, PEEe)
            return self.apply_measurement_weighting(raw, pos_weight=1.0, orient_weight=0.5)

    opts = job["options"]
    variant = f"{opts.get('model', 'full_params')}/{opts.get('estimation', 'structural')}"
    joints = list(job["joint_names"])
    q_train = np.asarray(job["q_train"], dtype=float)
    p_train = np.asarray(job["p_train"], dtype=float)
    q_test = np.asarray(job["q_test"], dtype=float)
    notes = []

    # kinematics only: FIGAROH's load_robot would also load meshes via package paths
    model = pin.buildModelFromUrdf(job["urdf"])
    robot = RobotWrapper(model)
    for name in joints:
        if not model.existJointName(name):
            raise ValueError(f"joint {name!r} not in {job['urdf']}")
        others = [m for m in model.names[1:] if m != name and name in m]
        if others:  # FIGAROH matches parameters to joints by substring
            notes.append(f"WARNING joint name {name!r} is a substring of {others}: "
                         "FIGAROH's name matching may mix their parameters")

    with tempfile.TemporaryDirectory(prefix="figaroh_job_") as tmp:
        csv_path = os.path.join(tmp, "calibration.csv")
        cfg_path = os.path.join(tmp, "config.yaml")
        write_csv(csv_path, joints, q_train, p_train)
        write_config(cfg_path, job, csv_path, len(q_train), model.name or "robot")

        calib = PeerCalibration(robot, cfg_path)
        # not read from the YAML by FIGAROH: both frames unknown (its examples do this)
        calib.calib_config["known_baseframe"] = False
        calib.calib_config["known_tipframe"] = False
        calib.load_data_set()  # initialize() = load_data_set() + create_param_list()

        t0, c0 = time.perf_counter(), time.process_time()
        calib.create_param_list()
        t1, c1 = time.perf_counter(), time.process_time()

        solver_time = {}
        inner = calib.solve_optimisation

        def timed_solve_optimisation(*a, **k):
            s, c = time.perf_counter(), time.process_time()
            try:
                return inner(*a, **k)
            finally:
                solver_time["t"] = time.perf_counter() - s
                solver_time["cpu"] = time.process_time() - c

        calib.solve_optimisation = timed_solve_optimisation
        guess = calib.initial_frame_guess()
        if not guess:
            notes.append("no closed-form frame guess: tip starts at tool_guess")
        t2 = time.perf_counter()
        var_init = None
        if not guess:
            var_init = np.zeros(len(calib.calib_config["param_name"]))
            tg = np.asarray(job.get("tool_guess", np.zeros(3)), dtype=float)
            for i, nm in enumerate(calib.calib_config["param_name"]):
                for k, e in enumerate(("pEEx_1", "pEEy_1", "pEEz_1")):
                    if nm == e:
                        var_init[i] = tg[k]
            result, outliers = calib.solve_optimisation(
                var_init=var_init, max_iterations=int(opts.get("max_iterations", 3)))
            solve_total = time.perf_counter() - t2
            var = result.x
            n_out = len(outliers)
        else:
            result = calib.solve(max_iterations=int(opts.get("max_iterations", 3)),
                                 enable_logging=False)
            solve_total = time.perf_counter() - t2
            var = calib.var_
            n_out = len(calib.outlier_indices)

        cfg = calib.calib_config
        names = list(cfg["param_name"])
        q0 = np.asarray(cfg["q0"], dtype=float)
        idx = list(cfg["config_idx"])

        def predict(Q):
            Qf = np.tile(q0, (len(Q), 1))
            Qf[:, idx] = Q
            flat = calc_updated_fkm(calib.model, calib.data, var, Qf, dict(cfg, NbSample=len(Q)))
            return flat.reshape(3, len(Q)).T  # component-major -> (K, 3)

        p_fit = predict(q_train)
        p_pred = predict(q_test)

    dropped = cfg.get("absorbed_param_name") or []
    if dropped:
        notes.append(f"absorbed by the frames on this data, dropped: {dropped}")
    if cfg.get("estimation_report"):
        rep = cfg["estimation_report"]
        notes.append("estimation report: " + json.dumps(
            {k: rep[k] for k in rep if isinstance(rep[k], (int, float, str))}, default=str))
    notes.append("structural parameter selection uses NbSample random postures "
                 "(seeded), then a finite-difference Jacobian on the data")
    notes.append("solver: scipy least_squares method='lm', finite-difference Jacobian, "
                 "max_nfev=1000 per fit, outlier refits")
    if not bool(getattr(result, "success", True)):
        notes.append(f"least_squares did not converge: {getattr(result, 'message', '')}")
    out = dict(
        p_pred=p_pred, p_fit=p_fit,
        fit_time_s=(t1 - t0) + solver_time.get("t", solve_total),
        fit_cpu_s=(c1 - c0) + solver_time.get("cpu", float("nan")),
        select_time_s=t1 - t0, solver_time_s=solver_time.get("t", solve_total),
        solve_total_s=solve_total,
        n_params=int(len(names)), param_names=names, param_values=np.asarray(var, dtype=float),
        n_outliers=int(n_out), nfev=int(getattr(result, "nfev", -1)),
        success=bool(getattr(result, "success", True)),
        status_message=str(getattr(result, "message", "")),
        rms_train_mm=rms_mm(p_fit, p_train),
        peer=PEER, peer_version=_version("figaroh"), pinocchio_version=pin.__version__,
        numpy_version=np.__version__, variant=variant, input_used="urdf+joint_names+frames",
        notes="\n".join(notes), error="",
    )
    if job.get("p_test") is not None:
        out["rms_test_mm"] = rms_mm(p_pred, job["p_test"])
    return out


def _version(dist: str) -> str:
    try:
        from importlib.metadata import version
        return version(dist)
    except Exception:  # pragma: no cover
        return "unknown"


def _quiet():
    """FIGAROH prints its quality report and warnings: keep stdout for the summary."""
    stack = contextlib.ExitStack()
    stack.enter_context(contextlib.redirect_stdout(sys.stderr))
    stack.enter_context(warnings.catch_warnings())
    warnings.simplefilter("ignore")
    return stack


def main(argv=None) -> int:
    return worker_main(PEER, run, __doc__.splitlines()[0], argv, quiet=_quiet)


if __name__ == "__main__":
    sys.exit(main())
