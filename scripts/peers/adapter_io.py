"""Job input/output shared by the peer adapters (each runs in its peer's own venv).

Imported as a sibling module: an adapter run as a script has its own folder first on
sys.path. Plain numpy and the standard library only, so it works in every venv.

Job (``.npz``; any non-array field may instead come from a JSON side file given with
``--meta`` or found next to the job as ``JOB.json``; the JSON wins):

    q_train     (N, n) joint values of the chain joints, root first [rad | m]
    p_train     (N, 3) measured tool-point positions in the measurement frame M [m]
    q_test      (K, n) joint values to predict [rad | m]
    p_test      (K, 3) optional; only used to report rms_test_mm
    ...         the fields each adapter documents

Output (``.npz``): the adapter's fields; on failure ``error`` and ``traceback``.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import traceback

import numpy as np

SUMMARY_KEYS = ("peer", "variant", "n_params", "fit_time_s", "rms_train_mm", "rms_test_mm")


def _plain(value):
    """npz 0-d string arrays -> str, string arrays -> list of str."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "US":
        return str(value) if value.ndim == 0 else [str(v) for v in value]
    return value


def load_job(path: str, meta_path: str | None = None) -> dict:
    """The job's arrays from the .npz, updated by the JSON side file (which wins)."""
    with np.load(path, allow_pickle=False) as z:
        job = {k: _plain(z[k]) for k in z.files}
    if meta_path is None:
        side = os.path.splitext(path)[0] + ".json"
        meta_path = side if os.path.exists(side) else None
    if meta_path:
        with open(meta_path, encoding="utf-8") as f:
            job.update(json.load(f))
    opts = job.get("options", {})
    if isinstance(opts, str):
        opts = json.loads(opts) if opts.strip() else {}
    job["options"] = opts
    if isinstance(job.get("joint_names"), str):
        job["joint_names"] = [job["joint_names"]]
    return job


def save_output(path: str, out: dict) -> None:
    arrays = {}
    for k, v in out.items():
        if isinstance(v, (list, tuple)) and v and isinstance(v[0], str):
            arrays[k] = np.array(v, dtype=str)
        elif isinstance(v, str):
            arrays[k] = np.array(v)
        else:
            arrays[k] = np.asarray(v)
    np.savez(path, **arrays)


def rms_mm(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum((np.asarray(a) - np.asarray(b)) ** 2, axis=1))) * 1e3)


def worker_main(peer: str, run, description: str, argv=None, quiet=None) -> int:
    """JOB.npz OUT.npz [--meta JOB.json]: run the fit, write OUT, print a JSON summary.

    quiet: optional context-manager factory around ``run`` (e.g. to keep a peer's own
    printing off stdout). On failure OUT still gets ``error`` and ``traceback``; exit 1.
    """
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("job")
    ap.add_argument("out")
    ap.add_argument("--meta", default=None, help="JSON side file with the non-array fields")
    args = ap.parse_args(argv)
    try:
        job = load_job(args.job, args.meta)
        with (quiet() if quiet else contextlib.nullcontext()):
            out = run(job)
        save_output(args.out, out)
        print(json.dumps({k: out[k] for k in SUMMARY_KEYS if k in out}))
        return 0
    except Exception as exc:
        save_output(args.out, dict(peer=peer, error=f"{type(exc).__name__}: {exc}",
                                   traceback=traceback.format_exc(), success=False))
        print(traceback.format_exc(), file=sys.stderr)
        return 1
