"""Rotations and rigid transforms as plain numpy (no Pinocchio).

Conventions:
- URDF ``rpy`` = (roll, pitch, yaw) means R = Rz(yaw) @ Ry(pitch) @ Rx(roll) [rad].
- The measurement frame of the paper uses R = Rx(rx) @ Ry(ry) @ Rz(rz) [rad].
- Homogeneous transforms are 4x4 arrays; batches are (..., 4, 4).

The one home of the small pieces every module needs: cross products (:func:`skew`,
:func:`cross_rows`), Rodrigues' formula (:func:`axis_rotations`, its turn about an axis
line as fixed parts, :func:`turn_parts`, and the exponential and logarithm of rotation
vectors, :func:`rotation_exp`, :func:`rotation_log`), Kabsch's fit and quaternions.
"""

from __future__ import annotations

import math

import numpy as np


def rotx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def roty(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotations_about(axis: int, a: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations by the angles a (N,) about the x (0), y (1) or z (2) axis: the
    matrices of :func:`rotx`, :func:`roty`, :func:`rotz`, one per angle."""
    c, s = np.cos(a), np.sin(a)
    j, k = (axis + 1) % 3, (axis + 2) % 3
    R = np.zeros((len(a), 3, 3))
    R[:, axis, axis] = 1.0
    R[:, j, j], R[:, k, k], R[:, j, k], R[:, k, j] = c, c, -s, s
    return R


def transform(R: np.ndarray | None = None, p=None) -> np.ndarray:
    """4x4 homogeneous transform from rotation R (3x3) and translation p (3,) [m]."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4x4 or batch)."""
    R = T[..., :3, :3]
    p = T[..., :3, 3]
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, p)
    Ti[..., 3, 3] = 1.0
    return Ti


def rpy_to_matrix(rpy) -> np.ndarray:
    """URDF rpy [rad] to a rotation matrix: Rz(y) Ry(p) Rx(r)."""
    r, p, y = (float(v) for v in rpy)
    return rotz(y) @ roty(p) @ rotx(r)


def _wrap_near(angle: float, reference: float) -> float:
    """``angle`` plus the multiple of 2*pi that brings it closest to ``reference``."""
    return angle + 2.0 * math.pi * round((reference - angle) / (2.0 * math.pi))


def matrix_to_rpy(R: np.ndarray, near=(0.0, 0.0, 0.0)) -> np.ndarray:
    """URDF rpy [rad] of rotation R, chosen closest to the triple ``near``.

    A rotation has two rpy triples (r, p, y) and (r + pi, pi - p, y + pi), each
    modulo 2*pi per angle. Of these, the one closest to ``near`` (Euclidean, after
    wrapping each angle next to its reference) is returned, so a corrected origin
    keeps the look of its original numbers. At exact gimbal lock (|R[2,0]| = 1)
    only r - y (or r + y) is defined; roll is then kept at its reference value.
    The result reproduces R to machine precision in every case.
    """
    R = np.asarray(R, dtype=float)
    near = np.asarray(near, dtype=float)
    # pitch from atan2, well conditioned also near +-90 deg (asin is not)
    cp = math.hypot(R[2, 1], R[2, 2])
    p = math.atan2(-R[2, 0], cp)
    # roll from the last row; at exact gimbal lock it is free: keep the reference
    r = math.atan2(R[2, 1], R[2, 2]) if cp > 1e-300 else float(near[0])
    # yaw from what is left once roll and pitch are removed, so that the triple
    # reproduces R to machine precision even where roll alone is ill-conditioned
    M = R @ rotx(r).T @ roty(p).T
    y = math.atan2(M[1, 0], M[0, 0])
    candidates = [(r, p, y), (r + math.pi, math.pi - p, y + math.pi)]
    best, best_d = np.asarray(near, float), math.inf
    for c in candidates:
        w = np.array([_wrap_near(c[i], near[i]) for i in range(3)])
        d = float(np.sum((w - near) ** 2))
        if d < best_d:
            best, best_d = w, d
    return best


def xyz_rpy_to_transform(xyz, rpy) -> np.ndarray:
    return transform(rpy_to_matrix(rpy), np.asarray(xyz, dtype=float))


def base_rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    """Measurement-frame rotation of the paper: Rx(rx) Ry(ry) Rz(rz) [rad]."""
    return rotx(rx) @ roty(ry) @ rotz(rz)


def base_turns(rx: float, ry: float) -> np.ndarray:
    """(3, 3) columns: the axes about which the angles rx, ry, rz of R = Rx(rx) Ry(ry) Rz(rz)
    turn R, in the frame R maps into (e_x, Rx e_y, Rx Ry e_z): a small change d of the angles
    turns R by the rotation vector W d (the angles' Jacobian of the measurement frame, a
    tool frame, a flush contact frame (rx, ry only) and a placement error's turn)."""
    Rx = rotx(rx)
    return np.column_stack([np.eye(3)[0], Rx[:, 1], Rx @ roty(ry)[:, 2]])


def skew(v) -> np.ndarray:
    """(..., 3, 3) the cross-product matrices K of vectors v (..., 3): K u = v x u."""
    v = np.asarray(v, dtype=float)
    K = np.zeros(v.shape + (3,))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return K


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis, broadcasting (np.cross is slow on small batches)."""
    if a.shape != b.shape:
        a, b = np.broadcast_arrays(a, b)
    out = np.empty(a.shape)
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def axis_rotations(w, angles) -> np.ndarray:
    """(N, 3, 3) rotations by the angles (N,) [rad] about the unit axis w (3,), or about
    one unit axis per angle (N, 3): Rodrigues' formula R = c I + s K + (1 - c) w w^T, kincal's
    one writing of it (c, s the angle's cosine and sine, K = :func:`skew` (w))."""
    w, q = np.asarray(w, dtype=float), np.asarray(angles, dtype=float)
    c = np.cos(q)
    if w.ndim == 1:  # one axis: two (N, 3, 3) arrays made, no more
        R = np.multiply.outer(np.sin(q), skew(w))
        R += np.multiply.outer(1.0 - c, np.outer(w, w))
    else:
        R = np.sin(q)[:, None, None] * skew(w)
        R += (1.0 - c)[:, None, None] * (w[:, :, None] * w[:, None, :])
    R.reshape(len(R), 9)[:, ::4] += c[:, None]  # the diagonal, as a view (no gather)
    return R


def axis_rotation(w, angle: float) -> np.ndarray:
    """(3, 3) the rotation by ``angle`` [rad] about the unit axis w (3,): one
    :func:`axis_rotations`."""
    return axis_rotations(w, np.array([float(angle)]))[0]


def turn_parts(w, c) -> np.ndarray:
    """(..., 3, 3, 4): the turn by q about the axis line of unit direction w (..., 3)
    through the point c (..., 3), x -> R (x - c) + c, as [R | c - R c] = cos q P_0 + sin q
    P_1 + (1 - cos q) P_2 with these fixed parts (:func:`axis_rotations`' formula): P_0 =
    [I | 0], P_1 = [K | -K c], P_2 = [w w^T | c - w (w . c)], one set per axis line. The
    chains' motions are sums of them (:mod:`kincal.models.chain`,
    :mod:`kincal.models.kinematics`)."""
    w, c = np.asarray(w, dtype=float), np.asarray(c, dtype=float)
    K = skew(w)
    P = np.zeros(w.shape[:-1] + (3, 3, 4))
    P[..., 0, :, :3] = np.eye(3)
    P[..., 1, :, :3] = K
    P[..., 1, :, 3] = -np.einsum("...ij,...j->...i", K, c)
    P[..., 2, :, :3] = w[..., :, None] * w[..., None, :]
    P[..., 2, :, 3] = c - w * np.einsum("...i,...i->...", w, c)[..., None]
    return P


def rotation_angle(R: np.ndarray) -> float:
    """Geodesic angle [rad] of rotation R."""
    c = (np.trace(R) - 1.0) / 2.0
    s = np.linalg.norm([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    return math.atan2(s, c)


def tilt_angles(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rx, ry) [rad] of unit vectors m (..., 3) = Rx(rx) Ry(ry) e_z, ry in [-pi/2, pi/2]
    (both by atan2: well conditioned also near ry = +-90 deg, where arcsin is not): the
    tilts of a plane's normal (:mod:`kincal.measurements.plane`), a flush contact frame's
    (:mod:`kincal.measurements.flush`), an axis (:func:`kincal.models.mdh.hayati_parameters`)
    and the first two :func:`base_angles`; :func:`kincal.measurements.plane.normal` is its
    inverse."""
    m = np.asarray(m, dtype=float)
    return (np.arctan2(-m[..., 1], m[..., 2]),
            np.arctan2(m[..., 0], np.hypot(m[..., 1], m[..., 2])))


def base_angles(R: np.ndarray) -> np.ndarray:
    """(..., 3) the angles (rx, ry, rz) [rad] with R = Rx(rx) Ry(ry) Rz(rz) of rotations R
    (..., 3, 3), ry in [-pi/2, pi/2], giving R back to rounding also at gimbal lock (ry =
    +-90 deg, where only rx + rz, or rx - rz, is defined): rx and ry the
    :func:`tilt_angles` of R's last column; rz from R's first row, cos(ry) (cos rz,
    -sin rz, .), where cos(ry) >= 1/8 (to rounding there), and nearer the lock from
    Rx(rx)^T R = Ry(ry) Rz(rz), whose middle row is (sin rz, cos rz, 0) whatever ry. One
    rotation (3, 3) in Python numbers (math's atan2 and hypot: the bits of the frame starts,
    one or two a fit, and a sixth of the cost)."""
    R = np.asarray(R, dtype=float)
    if R.ndim == 2:
        (a, b, p), (d, e, f), (g, h, i) = R.tolist()
        cy, x = math.hypot(f, i), math.atan2(-f, i)
        if cy >= 0.125:
            return np.array([x, math.atan2(p, cy), math.atan2(-b, a)])
        cx, sx = math.cos(x), math.sin(x)
        return np.array([x, math.atan2(p, cy), math.atan2(cx * d + sx * g, cx * e + sx * h)])
    rx, ry = tilt_angles(R[..., :, 2])
    c, s = np.cos(rx), np.sin(rx)
    rz = np.where(np.hypot(R[..., 1, 2], R[..., 2, 2]) >= 0.125,
                  np.arctan2(-R[..., 0, 1], R[..., 0, 0]),
                  np.arctan2(c * R[..., 1, 0] + s * R[..., 2, 0],
                             c * R[..., 1, 1] + s * R[..., 2, 1]))
    return np.stack([rx, ry, rz], axis=-1)


def kabsch(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid (R, t) minimising sum ||y_k - (R x_k + t)||^2 for (N, 3) point sets; x a stack
    (S, N, 3) of sets against the one y: (R (S, 3, 3), t (S, 3)), each set's numbers those
    of its own call (products of stacks go matrix by matrix; means over the same axis)."""
    if x.ndim == 2:
        xm, ym = x.mean(axis=0), y.mean(axis=0)
        R = kabsch_rotation((x - xm).T @ (y - ym))
        return R, ym - R @ xm
    xm, ym = x.mean(axis=1), y.mean(axis=0)
    R = kabsch_rotation(np.matmul(np.swapaxes(x - xm[:, None], 1, 2), y - ym))
    return R, ym - np.matmul(R, xm[:, :, None])[:, :, 0]


_FLIP = np.array([1.0, 1.0, -1.0])


def kabsch_rotation(H: np.ndarray) -> np.ndarray:
    """Kabsch's rotation V diag(1, 1, det(V U^T)) U^T from the cross-covariance H = U S V^T:
    V U^T, or V diag(1, 1, -1) U^T where that is a reflection (the products with the
    diagonal's ones and zeros are exact: the same numbers as forming V D U^T always). The
    sign of det(V U^T) (+-1 to rounding: the same sign however it is summed) from its
    cofactors in Python numbers, a sixth of np.linalg.det's cost: the closed-form frame
    start runs this up to 18 times a fit. H (..., 3, 3): one rotation per matrix, each the
    numbers of its own call (numpy's SVD and products go matrix by matrix)."""
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    R = V @ np.swapaxes(U, -1, -2)
    if R.ndim == 2:
        return R if _proper(R.tolist()) else (V * _FLIP) @ U.T
    flat = R.reshape(-1, 3, 3)
    for k, Rk in enumerate(flat.tolist()):
        if not _proper(Rk):
            flat[k] = (V.reshape(-1, 3, 3)[k] * _FLIP) @ U.reshape(-1, 3, 3)[k].T
    return R


def _proper(R) -> bool:
    """Whether the 3 x 3 rows R (Python numbers) have a determinant >= 0 (by cofactors)."""
    (a, b, c), (d, e, f), (g, h, i) = R
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) >= 0


def quaternion_to_matrix(q) -> np.ndarray:
    """Rotation matrix of the unit quaternion q = (qx, qy, qz, qw), scalar last.

    Batches (..., 4) give (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                  2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                  2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1)
    return R.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (qx, qy, qz, qw), scalar last and qw >= 0, of rotation R (3, 3).

    Shepperd's method: the largest of the four squared components is taken from the
    diagonal, the others from off-diagonal sums, so no branch divides by a small number."""
    R = np.asarray(R, dtype=float)
    t = np.trace(R)
    k = int(np.argmax([R[0, 0], R[1, 1], R[2, 2], t]))
    if k == 3:
        s = 2.0 * math.sqrt(1.0 + t)
        q: list[float] = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, s / 4]
    else:
        i, j, m = k, (k + 1) % 3, (k + 2) % 3
        s = 2.0 * math.sqrt(1.0 + R[i, i] - R[j, j] - R[m, m])
        q = [0.0] * 4
        q[i] = s / 4
        q[j] = (R[j, i] + R[i, j]) / s
        q[m] = (R[m, i] + R[i, m]) / s
        q[3] = (R[m, j] - R[j, m]) / s
    v = np.array(q)
    return v if v[3] >= 0 else -v


def rotation_exp(phi: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations of rotation vectors phi (N, 3) [rad]: :func:`axis_rotations` about
    phi / |phi| by |phi|, the inverse of :func:`rotation_log` (series where |phi| < 1e-8)."""
    theta = np.linalg.norm(phi, axis=1)
    small = theta < 1e-8
    t = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta ** 2 / 6.0, np.sin(t) / t)
    b = np.where(small, 0.5 - theta ** 2 / 24.0, (1.0 - np.cos(t)) / t ** 2)
    K = skew(phi)
    return np.eye(3) + a[:, None, None] * K + b[:, None, None] * (K @ K)


def rotation_log(R: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors [rad] of rotations (N, 3, 3) (angle in [0, pi]), to rounding at
    every angle: the axis from the antisymmetric part R - R^T = 2 sin(angle) [axis]x up to
    90 deg; beyond, where sin(angle) shrinks toward pi, from the symmetric part,
    (R + R^T) / 2 - cos(angle) I = (1 - cos(angle)) axis axis^T (its row of largest
    diagonal, the sign from the antisymmetric part's)."""
    w = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], 1)
    s = np.linalg.norm(w, axis=1) / 2.0
    c = (np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0
    angle = np.arctan2(s, c)
    small = s < 1e-9
    scale = np.where(small, 0.5, angle / (2.0 * np.where(small, 1.0, s)))
    out = w * scale[:, None]
    wide = np.flatnonzero(c < 0.0)  # beyond 90 deg
    if wide.size:
        Rw, cw = R[wide], c[wide]
        B = (Rw + np.swapaxes(Rw, 1, 2)) / 2.0
        B.reshape(-1, 9)[:, ::4] -= cw[:, None]  # (1 - c) axis axis^T
        k = np.argmax(np.diagonal(B, axis1=1, axis2=2), axis=1)
        row = B[np.arange(wide.size), k]  # (1 - c) axis_k axis
        axis = row / np.linalg.norm(row, axis=1)[:, None]
        axis *= np.where(np.sum(axis * w[wide], axis=1) < 0.0, -1.0, 1.0)[:, None]
        out[wide] = axis * angle[wide, None]
    return out


def aligned_distances(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(M,) distances between point sets A and B after the best rigid motion of B onto A."""
    a, b = A - np.add.reduce(A) / len(A), B - np.add.reduce(B) / len(B)  # np.mean's sums
    return np.linalg.norm(a - b @ kabsch_rotation(b.T @ a).T, axis=1)  # a = R b, as rows
