"""The flush kind: a flat face of the tool pressed flat on a plane at every sample (a
gripper's palm on a table, a probe's flat foot on a surface plate). Joint columns only.

Plain numpy. Plane k is ``{P: n_k . P = d_k}`` in the robot's base frame with the unit
normal ``n_k = Rx(rx) Ry(ry) e_z`` (as in :mod:`.plane`). The contact frame sits on the tip
at ``t`` (the contact point, [m] in the tip frame) turned by ``R_c = Rx(tool.rx)
Ry(tool.ry)``; its z axis ``u = R_c e_z`` (tip frame) is the face's normal. A flush touch
fixes 3 of the contact frame's 6 degrees of freedom; the residuals per sample, measured
(flush: zero) minus predicted, are

    height  d - n . p_tip - u . t                                    [m]
    tilts   -c (alpha, beta)                                         [rad] * c [m/rad]

where ``m = (R_tip R_c)^T n`` is the plane's normal seen in the contact frame and
``m = Rx(alpha) Ry(beta) e_z``: alpha is the contact frame's roll (about its x axis) and
beta its pitch (about its y axis) against the plane. ``c = sigma / sigma_orientation``
turns the tilt rows into metres as the pose kind does, so that both weigh by their stated
noise (default: :data:`DEFAULT_TILT_SIGMA_DEG` against the length sigma, 0.05 mm: one
degree of tilt weighs like 1 mm of height).

The height is the contact point's height as it is when the face lies flush (``R_tip u =
n``); it differs from the height of ``p_tip + R_tip t`` by ``(R_tip^T n - u) . t``, which
the tilt rows see. Why: flush touches cannot see where the contact point is. Its position
across the face normal changes nothing, and along the normal it shifts every touch's
height alike, as the plane's offset does. With the point's own height the columns of
``tool.x .y .z`` differ from the plane offset's only through the tilt noise, and a fit
would move the point by the heights divided by the tilts; with this height they are
exactly the offset's, so the rank-revealing selection drops them and holds the point at its
start (``--tool-offset``). For that the plane names come first among the frames: the
selection keeps the earlier of two equivalent frame columns. A plane several files share
(``--shared-plane``) sees the difference of their contact heights: one contact point then
moves, along its face normal, so the point's z (along u while the tilts are small) comes
before its x and y.

Frame names: ``plane.rx .ry .d`` with one plane, or ``plane<label>.*`` for each label of a
``plane`` column, then ``tool.rx .ry .z .x .y`` (the contact frame: the pose kind's tool
frame, without the turn about the normal, ``tool.rz``, that flush touches cannot see).
The tilts are singular for a normal along +-x (ry = +-90 deg), as the plane's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kincal.errors import DataError, IdentifiabilityError
from kincal.measurements.checks import SIGMA_RANGE_DEG
from kincal.measurements.csv_table import csv_line
from kincal.measurements.kind import DEFAULT_SIGMA, KindModel, SampleSet, read_set, readonly
from kincal.measurements.plane import (MIN_SPREAD, fit_plane, normal, normal_by_ry, plane_indices,
                                      plane_labels)
from kincal.rotations import base_turns, cross_rows, rotx, roty, skew, tilt_angles

DEFAULT_TILT_SIGMA_DEG = 0.05  # [deg] tilt noise assumed when a set states none
MIN_TOUCHES = 3  # per plane: its tilt and offset need three touches not on a line
# the contact point's z first: along the face normal u (= R_c e_z, the tilts small), the one
# component a height offset can move; the selection keeps the earlier of equivalent columns,
# and x first (u_x tiny) once ran off by metres where shared planes make that offset seen
TOOL_FRAMES = ("tool.rx", "tool.ry", "tool.z", "tool.x", "tool.y")
_XYZ = [1, 2, 0]  # the stored (z, x, y) read as (x, y, z)
_ZXY = [2, 0, 1]  # and (x, y, z) stored as (z, x, y)


@dataclass(frozen=True, kw_only=True)
class FlushData(SampleSet):
    """Flush touches: planes (N,) index of each touch's plane into labels; sigma (N,)
    height standard deviation [m]; sigma_deg (N,) tilt standard deviation [deg] (needs
    ``sigma``: the tilt rows weigh by the ratio of the two); orientation_sigma_deg: the
    tilt sigma when no sigma_deg is given [deg] (None: not stated, then
    :data:`DEFAULT_TILT_SIGMA_DEG` weighs the rows and the evidence estimates the noise of
    heights and tilts on their own)."""

    planes: np.ndarray | None = None
    labels: tuple[str, ...] = ("",)
    sigma_deg: np.ndarray | None = None
    orientation_sigma_deg: float | None = None

    kind = "flush"

    def __post_init__(self):
        super().__post_init__()
        n = len(self.joint_values)
        object.__setattr__(self, "planes", plane_indices(self))
        if self.sigma_deg is not None:
            if self.sigma is None:
                raise DataError(f"{self.source}: a tilt sigma (sigma_deg) needs a height sigma "
                                "(sigma [length]) beside it: the tilt rows weigh by their ratio; "
                                "give both columns, or neither (then orientation_sigma_deg)")
            s = readonly(self.sigma_deg)
            if s.shape != (n,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
                raise DataError(f"{self.source}: sigma_deg must be {n} positive finite values "
                                "[deg]")
            object.__setattr__(self, "sigma_deg", s)
        o = self.orientation_sigma_deg
        lo, hi = SIGMA_RANGE_DEG  # as a pose set's orientation sigma
        if o is not None and not (math.isfinite(o) and lo <= o <= hi):
            raise DataError(f"the tilt sigma of flush touches must be a finite value between "
                            f"{lo:g} and {hi:g} deg, got {self.orientation_sigma_deg}")

    def per_sample_fields(self):
        return super().per_sample_fields() + ("planes", "sigma_deg")

    def ratio(self) -> np.ndarray:
        """(N,) c = sigma_height / sigma_tilt [m/rad]."""
        sh = np.full(len(self), DEFAULT_SIGMA) if self.sigma is None else self.sigma
        o = self.orientation_sigma_deg
        st = (np.full(len(self), DEFAULT_TILT_SIGMA_DEG if o is None else o)
              if self.sigma_deg is None else self.sigma_deg)
        return sh / np.radians(st)

    @classmethod
    def from_csv(cls, path, joint_names, prismatic=(), length_unit="m", angle_unit="rad",
                 plane_column="plane", joint_columns=None,
                 orientation_sigma_deg=None) -> "FlushData":
        """Joint columns; optional ``plane`` (a whole number naming each touch's plane),
        ``sigma`` [length unit] and ``sigma_deg`` [deg, whatever the angle unit].
        orientation_sigma_deg: the tilt sigma of rows without sigma_deg [deg]; None: not
        stated (:class:`FlushData`)."""
        c = read_set(path, joint_names, (), (plane_column, "sigma", "sigma_deg"), prismatic,
                     angle_unit, length_unit, joint_columns, expected="the chain joints")
        v = c.values
        L = 1e-3 if length_unit == "mm" else 1.0
        planes, labels = (plane_labels(v[plane_column], c.source, c.rows, plane_column)
                          if plane_column in v else (None, ("",)))
        for name in ("sigma", "sigma_deg"):
            if name in v and np.any(v[name] <= 0):
                k = int(np.argmax(v[name] <= 0))
                raise DataError(f"{c.source}, line {c.rows[k]}, column {name!r}: must be > 0")
        if "sigma_deg" in v and "sigma" not in v:
            raise DataError(f"{c.source}: column 'sigma_deg' without a 'sigma' column: the tilt "
                            "rows weigh by the ratio of the height sigma to the tilt sigma; add "
                            "'sigma' [length unit] or drop 'sigma_deg'")
        check_touch_counts(np.zeros(len(c.rows), int) if planes is None else planes, labels,
                           c.source)
        return cls(joint_names=tuple(joint_names), joint_values=c.joint_values,
                   angle_unit=angle_unit, planes=planes,
                   labels=labels, sigma=v["sigma"] * L if "sigma" in v else None,
                   sigma_deg=v.get("sigma_deg"),
                   orientation_sigma_deg=orientation_sigma_deg,
                   rows=c.rows, source=c.source, approach=c.approach, ignored_columns=c.ignored)

    def to_csv_text(self) -> str:
        """The touches in the layout :meth:`from_csv` reads (SI units, full precision)."""
        cols, table = list(self.joint_names), [self.joint_values]
        if self.labels != ("",):
            assert self.planes is not None  # filled in by __post_init__
            cols.append("plane")
            table.append(np.array([[float(self.labels[k])] for k in self.planes]))
        for name in ("sigma", "sigma_deg"):
            if getattr(self, name) is not None:
                cols.append(name)
                table.append(getattr(self, name)[:, None])
        rows = np.hstack(table)
        lines = [csv_line(cols)] + [csv_line(repr(float(x)) for x in row) for row in rows]
        return "\n".join(lines) + "\n"


def check_touch_counts(planes: np.ndarray, labels, source: str) -> None:
    """DataError if a plane has fewer touches than its tilt and offset need."""
    for j, label in enumerate(labels):
        count = int(np.sum(planes == j))
        if count < MIN_TOUCHES:
            name = "the plane" if label == "" else f"plane {label}"
            raise DataError(
                f"{source}: {count} flush touch(es) on {name}; at least {MIN_TOUCHES} per plane, "
                "not on one line, are needed: the plane's two tilts and offset and the contact "
                "frame's height and two tilts are 6 unknowns, each touch gives 3 equations, "
                "and the heights of 3 touches not on a line fix the plane's tilt")


def tilt_gradient(m: np.ndarray) -> np.ndarray:
    """(N, 2, 3) derivatives of (alpha, beta) of :func:`kincal.rotations.tilt_angles` w.r.t. m."""
    mx, my, mz = m.T
    rho = np.hypot(my, mz)
    G = np.zeros((len(m), 2, 3))
    G[:, 0, 1] = -mz / rho ** 2
    G[:, 0, 2] = my / rho ** 2
    q = mx ** 2 + rho ** 2
    G[:, 1, 0] = rho / q
    G[:, 1, 1] = -mx * my / (rho * q)
    G[:, 1, 2] = -mx * mz / (rho * q)
    return G


def angles_of(u: np.ndarray) -> tuple[float, float]:
    """(rx, ry) [rad] with Rx(rx) Ry(ry) e_z along the unit vector u."""
    a, b = tilt_angles(u)
    return float(a), float(b)


class FlushKind(KindModel):
    """Residuals and Jacobian of flush touches (see the module notes)."""

    kind = "flush"
    dim = 3
    data: FlushData

    def __init__(self, error_model, data, backlash=(), compliance=(), torque=None):
        super().__init__(error_model, data, backlash, compliance, torque)
        labels = self.data.labels
        prefixes = ["plane"] if labels == ("",) else [f"plane{lab}" for lab in labels]
        self.frame_names = tuple(
            f"{p}.{c}" for p in prefixes for c in ("rx", "ry", "d")) + TOOL_FRAMES
        self.frame_is_length = (False, False, True) * len(labels) + (False,) * 2 + (True,) * 3

    def split_frames(self, frames):
        """(planes (k, 3) rows rx, ry [rad], d [m]; tool tilts (2,) [rad]; tool point (3,)
        [m])."""
        k = 3 * len(self.data.labels)
        return frames[:k].reshape(-1, 3), frames[k:k + 2], frames[k + 2:k + 5][_XYZ]

    def residuals(self, kin, frames, backlash, jacobian=False, kinematic=True):
        pl, a, t = self.split_frames(frames)
        k = self.data.planes
        s = self.chain.state(kin, backlash, keep=jacobian and kinematic)
        Rx = rotx(a[0])
        Rc = Rx @ roty(a[1])
        u = Rc[:, 2]                                              # face normal, tip frame
        A = s.R_tip @ Rc                                          # contact frame (N, 3, 3)
        n = np.array([normal(x, y) for x, y, _ in pl])[k]         # (N, 3)
        m = np.einsum("nji,nj->ni", A, n)                         # normal in the contact frame
        alpha, beta = tilt_angles(m)
        c = self.data.ratio()
        r = np.column_stack([pl[k, 2] - np.sum(n * s.p_tip, axis=1) - u @ t,
                             -c * alpha, -c * beta])
        if not jacobian:
            return r
        N = self.N
        G = -c[:, None, None] * tilt_gradient(m)                  # d(tilt rows)/dm
        # a small turn w (base frame) of the contact frame changes m by A^T [n]x w
        S = G @ np.einsum("nji,njk->nik", A, skew(n))   # d(tilt rows)/d(turn)
        if kinematic:
            Kp, Bp = s.point_columns(s.p_tip)
            Kr, Br = s.rotation_columns()
            Jk = np.concatenate([-np.einsum("ni,nip->np", n, Kp)[:, None, :], S @ Kr], axis=1)
            Jb = np.concatenate([-np.einsum("ni,nip->np", n, Bp)[:, None, :], S @ Br], axis=1)
        else:
            Jk, Jb = self._zero_chain_columns(3)
        Jf = np.zeros((N, 3, self.n_frames))
        rows = np.arange(N)
        ex = np.eye(3)[0]
        dn_rx = cross_rows(ex, n)
        dn_ry = np.stack([normal_by_ry(x, y) for x, y, _ in pl])[k]
        GA = np.einsum("nrj,nij->nri", G, A)                      # d(tilt rows)/dn
        for col, dn in ((3 * k, dn_rx), (3 * k + 1, dn_ry)):
            Jf[rows, 0, col] = -np.sum(dn * s.p_tip, axis=1)
            Jf[rows, 1:, col] = np.einsum("nri,ni->nr", GA, dn)
        Jf[rows, 0, 3 * k + 2] = 1.0
        f = 3 * len(self.data.labels)
        W = base_turns(a[0], a[1])[:, :2]                         # tool turns, tip frame
        Jf[:, 0, f:f + 2] = -(np.cross(W.T, u) @ t)               # d(u . t): turns of u
        Jf[:, 1:, f:f + 2] = S @ (s.R_tip @ W)
        Jf[:, 0, f + 2:f + 5] = -u[_ZXY]
        return r, Jk, Jf, Jb

    def check_fixable(self, kin, tool_guess=None) -> None:
        """Raise for a plane its touches cannot fix: fewer than three touches, or touches
        on (nearly) a line, at the kinematics ``kin``."""
        assert self.data.planes is not None  # filled in by FlushData.__post_init__
        check_touch_counts(self.data.planes, self.data.labels, self.data.source)
        s = self.chain.state(kin, None, keep=False)
        P = s.p_tip + s.R_tip @ (np.zeros(3) if tool_guess is None else
                                 np.asarray(tool_guess, float))
        for j, label in enumerate(self.data.labels):
            spread = fit_plane(P[self.data.planes == j])[2]
            if spread < MIN_SPREAD:
                name = "the plane" if label == "" else f"plane {label}"
                raise IdentifiabilityError(
                    f"{self.data.source}: the flush touches cannot fix {name}: they spread "
                    f"{spread * 1e3:.3f} mm across their best line (at least {MIN_SPREAD * 1e3:g} "
                    "mm is needed to fix its tilt); touch it at points not on one line")

    def start(self, kin, tool_guess=None):
        """Closed form: the contact point at ``tool_guess`` (zero if None); each plane
        fitted through the contact points; the face normal the mean of the planes' normals
        seen in the tip frame. A plane's normal, defined up to its sign, is turned to the
        face normal's side (the first plane's to the tip's +z side), so that a face on any
        side of the tip starts near its true tilt; each offset then from the heights of
        the module notes."""
        self.check_fixable(kin, tool_guess)
        t = np.zeros(3) if tool_guess is None else np.asarray(tool_guess, float)
        s = self.chain.state(kin, None, keep=False)
        P = s.p_tip + s.R_tip @ t
        normals, u = [], np.zeros(3)
        for j in range(len(self.data.labels)):
            on = self.data.planes == j
            n = fit_plane(P[on])[0]
            seen = np.einsum("nji,j->i", s.R_tip[on], n)           # sum of R_tip^T n
            if np.dot(seen, u if j else np.array([0.0, 0.0, 1.0])) < 0:
                n, seen = -n, -seen
            u = u + seen
            normals.append(n)
        u = u / np.linalg.norm(u)
        planes = [[*angles_of(n), float(np.mean(s.p_tip[self.data.planes == j] @ n) + u @ t)]
                  for j, n in enumerate(normals)]
        return np.concatenate([np.ravel(planes), angles_of(u), t[_ZXY]])

    def adopt(self, start, given, own) -> np.ndarray:
        """The start ``start`` (f,) with the shared planes' values ``given`` where ``own``
        is False (a plane another set also touches): the face normal is turned to their
        side when this set's own fit of a shared plane found it the other way up."""
        out = np.where(own, start, given)
        planes, _, _ = self.split_frames(start)
        theirs, a, _ = self.split_frames(out)
        shared = [j for j in range(len(planes)) if not own[3 * j]]
        if shared and normal(*planes[shared[0], :2]) @ normal(*theirs[shared[0], :2]) < 0:
            u = normal(*a)
            f = 3 * len(planes)
            out[f:f + 2] = angles_of(-u)
        return out

    def sample_errors(self, r):
        """(N,) the contact point's height above its plane, unsigned [m]."""
        return np.abs(r[:, 0])

    def tilt_errors(self, r) -> np.ndarray:
        """(N, 2) the contact frame's roll and pitch against its plane [rad] (signed,
        predicted minus flush) from the residual rows."""
        return -r[:, 1:] / self.data.ratio()[:, None]

    def angle_rows(self, r) -> np.ndarray:
        """(N, 2) a touch's orientation error, its tilt (:meth:`tilt_errors`), signed as the
        residual rows are (flush minus predicted) [rad]."""
        return -self.tilt_errors(r)

    def noise_rows(self):
        """(height [mm], tilt [deg], tilt [deg]): a touch's residual rows (module notes)."""
        tilt = self.data.ratio() * (math.pi / 180.0)
        return (("height", "mm", np.full(self.N, 1e-3)), ("tilt", "deg", tilt),
                ("tilt", "deg", tilt))

    def noise_stated(self) -> bool:
        """Whether the touches state a noise: ``sigma``, ``sigma_deg``, or the tilt sigma."""
        d = self.data
        return (d.sigma is not None or d.sigma_deg is not None
                or d.orientation_sigma_deg is not None)

    def notes(self):
        return (f"{self.data.source}: a flush touch sees the contact frame's height above the "
                "plane and its two tilts, not where on the plane it lands nor its turn about "
                "the plane's normal: the contact point (tool.x .y .z) is held at its start "
                "(--tool-offset; its offset along the face normal is the plane's offset's), "
                "what moves the tip within the plane or about its normal is not identified, "
                "and the planes are in the base frame",)


def planning_set(error_model, q, tool, planes=None) -> tuple[FlushData, np.ndarray]:
    """(touches, frames) for planning flush touches at candidate poses q (M, n): planes
    (M,) plane index of each candidate (default one plane); the frames from the closed-form
    start at the nominal kinematics (each plane fitted through the candidates' contact
    points at ``tool`` [m, tip frame], which touch it flush)."""
    k = np.zeros(len(q), int) if planes is None else np.asarray(planes, int)
    labels = ("",) if planes is None else tuple(str(j + 1) for j in range(int(k.max()) + 1))
    data = FlushData(joint_names=tuple(error_model.joint_names), joint_values=q, planes=k,
                     labels=labels, source="<candidate flush touches>")
    return data, FlushKind(error_model, data).start(error_model.nominal, tool)
