"""Synthetic measurements of every kind from a robot with known (planted) parameters.

Plain numpy, through the error model's chain (:mod:`kincal.models.chain`), so the data
are exactly what the kinds' models predict at the true parameters, plus Gaussian noise:

- points / poses: positions with ``noise`` [m] per axis; pose orientations turned by a
  random small rotation of ``noise_deg`` per axis;
- distances: ``|P - pivot| + noise``;
- plane contacts: candidate poses nearest each plane are moved onto it (minimum-norm
  joint steps, a few Newton iterations), then off it by ``noise`` along the normal;
- flush touches: likewise, the candidates whose contact frame is nearest flush with each
  plane moved flush, then off by ``noise`` in height and ``noise_deg`` in each tilt.

The candidates (tens of times as many as the touches wanted) are scored in blocks of
``BLOCK`` rows, keeping only the best so far: the chain's intermediates of all of them at
once took 2.8 GB for the 4.1 million candidates of 100,000 simulated contacts.
"""

from __future__ import annotations

import numpy as np

from kincal.errors import OptionError
from kincal.measurements.data import Measurements
from kincal.measurements.distance import DistanceData
from kincal.measurements.flush import FlushData
from kincal.measurements.plane import PlaneData, normal
from kincal.measurements.pose import PoseData
from kincal.models.base import ErrorModel
from kincal.models.chain import Chain
from kincal.rotations import base_rotation, rotation_exp, rotx, roty, tilt_angles

BLOCK = 65536  # candidates scored at once (bounds the memory of the chain's intermediates)


def nearest(score, candidates, k: int, block: int | None = None) -> np.ndarray:
    """Indices of the ``k`` candidates of smallest ``score(rows)`` ((B,) per block of rows),
    best first: ``np.argsort(score(candidates))[:k]`` without scoring all rows at once (ties,
    which random poses do not have, go to the earlier row)."""
    block = BLOCK if block is None else int(block)
    best_s, best_i = np.empty(0), np.empty(0, dtype=np.intp)
    for start in range(0, len(candidates), block):
        s = np.asarray(score(candidates[start:start + block]), float)
        best_s = np.concatenate([best_s, s])
        best_i = np.concatenate([best_i, np.arange(start, start + len(s))])
        keep = np.argsort(best_s, kind="stable")[:k]
        best_s, best_i = best_s[keep], best_i[keep]
    return best_i


def tool_points(model: ErrorModel, kin, q, tool) -> np.ndarray:
    """(N, 3) the tool point in the base frame [m] with kinematic parameters ``kin``."""
    s = Chain(model, q).state(np.asarray(kin, float), None, keep=False)
    return s.p_tip + s.R_tip @ np.asarray(tool, float)


def simulate_points(model, kin, base, tool, q, noise, rng, source="<simulated points>"):
    P = tool_points(model, kin, q, tool) @ base_rotation(*base[3:]).T + base[:3]
    return Measurements(model.joint_names, q, P + rng.normal(size=P.shape) * noise,
                        source=source)


def simulate_poses(model, kin, base, tool6, q, noise, noise_deg, rng,
                   source="<simulated poses>") -> PoseData:
    """tool6: (x, y, z [m], rx, ry, rz [rad]) of the tool frame in the tip frame."""
    s = Chain(model, q).state(np.asarray(kin, float), None, keep=False)
    Rb = base_rotation(*base[3:])
    P = (s.p_tip + s.R_tip @ tool6[:3]) @ Rb.T + base[:3]
    R = Rb @ s.R_tip @ base_rotation(*tool6[3:])
    turn = rotation_exp(rng.normal(size=(len(q), 3)) * np.radians(noise_deg))
    return PoseData(joint_names=model.joint_names, joint_values=q,
                    positions=P + rng.normal(size=P.shape) * noise, rotations=turn @ R,
                    orientation_sigma_deg=max(noise_deg, 1e-6),
                    sigma=np.full(len(q), max(noise, 1e-9)), source=source)


def simulate_distances(model, kin, pivot, tool, q, noise, rng,
                       source="<simulated distances>") -> DistanceData:
    d = np.linalg.norm(tool_points(model, kin, q, tool) - pivot, axis=1)
    return DistanceData(joint_names=model.joint_names, joint_values=q,
                        distances=d + rng.normal(size=len(d)) * noise, source=source)


def simulate_contacts(model, kin, tool, planes, candidates, per_plane, noise, rng,
                      source="<simulated plane contacts>") -> PlaneData:
    """planes: (k, 3) rows (rx, ry [rad], d [m]); candidates: (M, n) joint values to start
    from (those nearest each plane are used, ``per_plane`` of them)."""
    planes = np.atleast_2d(np.asarray(planes, float))
    qs, ks = [], []
    for j, (rx, ry, d) in enumerate(planes):
        n = normal(rx, ry)
        q = candidates[nearest(lambda c: np.abs(tool_points(model, kin, c, tool) @ n - d),
                               candidates, per_plane)]
        target = d + rng.normal(size=len(q)) * noise
        for _ in range(20):  # Newton on the signed distance, minimum-norm joint steps
            s = tool_points(model, kin, q, tool) @ n - target
            if np.max(np.abs(s)) < 1e-13:
                break
            h = 1e-7
            G = np.column_stack([(tool_points(model, kin, q + h * e, tool) @ n - target - s) / h
                                 for e in np.eye(q.shape[1])])
            q = q - G * (s / np.maximum(np.sum(G * G, axis=1), 1e-12))[:, None]
        if np.max(np.abs(s)) > 1e-9:
            raise OptionError(f"plane {j + 1}: could not move the poses onto it; choose a plane "
                              "the tool point can reach")
        qs.append(q)
        ks.append(np.full(len(q), j))
    return PlaneData(joint_names=model.joint_names, joint_values=np.vstack(qs),
                     planes=np.concatenate(ks), labels=tuple(str(j + 1) for j in
                                                             range(len(planes))), source=source)


def flush_offsets(model, kin, q, contact, n, d) -> np.ndarray:
    """(N, 3) height [m] and roll, pitch [rad] of the contact frame ``contact`` (x, y, z,
    rx, ry in the tip frame) against the plane (n, d), at joint values q."""
    s = Chain(model, q).state(np.asarray(kin, float), None, keep=False)
    P = s.p_tip + s.R_tip @ np.asarray(contact[:3], float)
    A = s.R_tip @ (rotx(contact[3]) @ roty(contact[4]))
    alpha, beta = tilt_angles(np.einsum("nji,j->ni", A, n))
    return np.column_stack([P @ n - d, alpha, beta])


def simulate_flush(model, kin, contact, planes, candidates, per_plane, noise, noise_deg, rng,
                   source="<simulated flush touches>", limits=None) -> FlushData:
    """contact: (5,) the contact frame on the tip (x, y, z [m], rx, ry [rad]); planes:
    (k, 3) rows (rx, ry [rad], d [m]); candidates: (M, n) joint values to start from (those
    whose contact frame is nearest flush with each plane are used, ``per_plane`` of them).
    limits: (lower (n,), upper (n,)) joint limits the touches must respect, or None (then
    three times as many starts are tried and the first within the limits kept)."""
    planes = np.atleast_2d(np.asarray(planes, float))
    qs, ks = [], []
    for j, (rx, ry, d) in enumerate(planes):
        n = normal(rx, ry)
        want = per_plane if limits is None else 3 * per_plane

        def flatness(c):
            off = flush_offsets(model, kin, c, contact, n, d)
            return np.abs(off[:, 0]) / 0.1 + np.hypot(off[:, 1], off[:, 2])

        q = candidates[nearest(flatness, candidates, want)]
        target = np.column_stack([rng.normal(size=len(q)) * noise,
                                  rng.normal(size=(len(q), 2)) * np.radians(noise_deg)])
        for _ in range(50):  # Newton on (height, roll, pitch), minimum-norm joint steps
            g = flush_offsets(model, kin, q, contact, n, d) - target
            if np.max(np.abs(g)) < 1e-13:
                break
            h = 1e-7
            G = np.stack([(flush_offsets(model, kin, q + h * e, contact, n, d) - target - g) / h
                          for e in np.eye(q.shape[1])], axis=2)          # (N, 3, n)
            dq = (np.linalg.pinv(G) @ g[:, :, None])[:, :, 0]  # each row's min-norm step
            scale = np.minimum(1.0, 0.3 / np.maximum(np.abs(dq).max(axis=1), 1e-12))
            q = q - dq * scale[:, None]
        ok = np.max(np.abs(g), axis=1) <= 1e-9
        if limits is not None:
            lo, hi = limits
            ok &= np.all((q >= lo - 1e-9) & (q <= hi + 1e-9), axis=1)
        if ok.sum() < per_plane:
            raise OptionError(f"plane {j + 1}: could not bring the contact frame flush with it "
                              f"within the joint limits ({int(ok.sum())} of {per_plane} touches); "
                              "choose a plane the contact frame can lie flush on")
        q = q[ok][:per_plane]
        qs.append(q)
        ks.append(np.full(len(q), j))
    return FlushData(joint_names=model.joint_names, joint_values=np.vstack(qs),
                     planes=np.concatenate(ks), source=source,
                     labels=tuple(str(j + 1) for j in range(len(planes))))
