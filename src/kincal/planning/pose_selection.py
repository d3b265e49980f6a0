"""Which poses to measure: D-optimal selection of n poses from a set of candidates.

Plain numpy (the robot enters only through its geometry). Given M candidate joint
configurations, :func:`select_poses` chooses n of them that maximise

    log det(J_S^T J_S)

over the parameters the candidates can identify, where J_S stacks the 3 x p
identification Jacobians of the chosen poses (:mod:`kincal.measurement_model`, at the
nominal robot with the tool point guess). Under the linearised model with independent
noise of equal size on every axis, (J_S^T J_S)^-1 sigma^2 is the covariance of the
least-squares estimate, so maximising the determinant minimises the volume of its
confidence ellipsoid (D-optimality).

Units and columns. J is taken in reporting units (mm of position per mm or per degree of
parameter, as :mod:`kincal.selection`). Kincal's own identifiability analysis
(:func:`kincal.selection.analyze`, ordered rank-revealing QR) runs on the stacked
Jacobian of ALL candidates; the criterion uses only the columns it keeps, since a
redundant column would make every determinant zero. Those columns are then divided by
their RMS norm per pose over the candidate set, so that the average pose adds 1 to every
diagonal entry of the information matrix. Rescaling columns multiplies the determinant of
every set by the same constant, so it does not change which set is best; it makes the
reported log det free of units, and it gives the ridge below the same meaning for every
parameter. Predicted standard errors are given back in mm and deg.

Search. Greedy forward selection starts from the ridge ``RIDGE * I`` (so that the first
picks, with fewer than p/3 poses, have a finite objective: with a tiny ridge the greedy
step picks the pose whose Jacobian spans the largest volume of what is not yet
determined). Each step scores every remaining candidate at once by the determinant lemma
det(M + J_k^T J_k) = det(M) det(I_3 + J_k M^-1 J_k^T) and updates M^-1 by Woodbury.
As soon as the chosen poses determine every column, the ridge is removed (M^-1 and
log det recomputed once, exactly) and the rest works on J_S^T J_S itself. Then a
Fedorov exchange: the best swap of a chosen pose for an unchosen one over all pairs,
scored at once by the rank-6 version of the lemma, is made while it raises log det by
more than ``EXCHANGE_TOL``, at most ``max_swaps`` times. The result is a local optimum
for single swaps (not, in general, the global optimum, which is a combinatorial search).
Ties go to the lower candidate index; the whole procedure is deterministic.

Limits. D-optimality speaks about parameter variance under the model linearised at the
nominal robot and the tool guess, with equal independent noise per axis. It does not see
collisions, cable wrap, reachability of the measuring instrument (line of sight of a
laser tracker, the range of an R-test) or non-geometric errors: the candidates given must
already be safe and measurable poses; kincal only picks among them. The figures for the
measurement frame (base.*) are for a frame at the base's orientation; turning it changes
those three standard errors, not the selection.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kincal.errors import DataError, KincalWarning, OptionError
from kincal.measurements.point_space import MM, ParameterSpace
from kincal.identification.reduction import stacked_triangle
from kincal.identification.selection import RANK_TOL, analyze
from kincal.measurements.point import MeasurementModel
from kincal.models.kinematics import BLOCK
from kincal import models as error_models
from kincal.models.mdh import TOOL_AXIS_WARNING
from kincal.planning import i_optimal
from kincal.planning.d_optimal import EXCHANGE_TOL, RIDGE, SINGULAR  # noqa: F401 (public tolerances)
from kincal.planning.d_optimal import exchange as _exchange
from kincal.planning.d_optimal import greedy as _greedy

if TYPE_CHECKING:
    from kincal.robot import Robot

METHODS = ("D", "I")
RANDOM_SUBSETS = 20  # K random subsets for the baseline


# ------------------------------------------------------------------ result
def _readonly(a, dtype=float) -> np.ndarray:
    a = np.array(a, dtype=dtype)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class PoseSelection:
    """The outcome of :func:`select_poses`.

    indices: the chosen candidates (row indices), in the order chosen (``keep`` first; a
        pose brought in by the exchange takes the place of the one it replaced).
    joint_values: (n, n_joints) the chosen poses [rad or m], chain order.
    parameters: the parameters the candidates identify (the columns of the criterion);
        units: "mm" or "deg" for each. not_identifiable: free parameters the candidate set
        cannot identify (redundant with others, or no effect); fixed: held by the user.
    lost: parameters the candidates identify but the chosen poses do not (normally empty).
    column_scale: (p,) RMS point motion per pose over the candidates [mm per mm or deg],
        the normalisation of each column.
    log_det: ln det of the normalised information matrix J_S^T J_S of the chosen set
        (-inf if singular). greedy_log_det: the same after the greedy stage.
    condition: condition number of the chosen set's information matrix scaled to unit
        diagonal (the square of the Jacobian condition number `kincal analyze` prints).
    variances: (p,) diag((J_S^T J_S)^-1) in reporting units, [mm^2 or deg^2 per mm^2 of
        noise]; :meth:`std_errors` turns them into standard errors.
    swaps, exchange_converged: exchanges made; False if ``max_swaps`` stopped them.
    random_log_det, random_condition, random_variances: the same figures for random
        subsets of the same size (median over ``random_subsets`` seeded draws; ``keep``
        is in every draw).
    model: the error model whose parameters the poses determine (kincal.models).
    criterion: "D" or "I" (:mod:`kincal.planning.i_optimal`). With target poses
        (n_targets of them): mean_variance, the mean predicted variance of the measured
        point over the targets per axis [mm^2 per mm^2 of noise], after the measurement
        frame and tool point are refitted there, and its random median.
    """

    chain: str
    joint_names: tuple[str, ...]
    n_candidates: int
    indices: tuple[int, ...]
    joint_values: np.ndarray
    parameters: tuple[str, ...]
    units: tuple[str, ...]
    not_identifiable: tuple[str, ...]
    fixed: tuple[str, ...]
    lost: tuple[str, ...]
    column_scale: np.ndarray
    log_det: float
    greedy_log_det: float
    condition: float
    variances: np.ndarray
    swaps: int
    exchange_converged: bool
    random_log_det: float
    random_condition: float
    random_variances: np.ndarray
    random_subsets: int
    ridge: float = RIDGE
    criterion: str = "D"
    mean_variance: float = math.nan
    random_mean_variance: float = math.nan
    n_targets: int = 0
    kind: str = "point"
    model: str = ""

    def noise_text(self, sigma_mm: float) -> str:
        """The noise the predicted errors are for, per equation of the kind: a distance or a
        height per contact; a pose's orientation and a flush touch's tilts weigh against the
        length noise as the sets weigh them when no sigma is stated (kincal's defaults)."""
        from kincal.measurements.flush import DEFAULT_TILT_SIGMA_DEG
        from kincal.measurements.kind import DEFAULT_SIGMA
        from kincal.measurements.pose import DEFAULT_ORIENTATION_SIGMA_DEG

        per_mm = sigma_mm / (DEFAULT_SIGMA * 1e3)
        return {"pose": f"{sigma_mm:g} mm per axis and "
                        f"{DEFAULT_ORIENTATION_SIGMA_DEG * per_mm:g} deg per orientation axis",
                "distance": f"{sigma_mm:g} mm per distance",
                "plane": f"{sigma_mm:g} mm per contact distance",
                "flush": f"{sigma_mm:g} mm per height and {DEFAULT_TILT_SIGMA_DEG * per_mm:g} "
                         "deg per tilt"}.get(self.kind, f"{sigma_mm:g} mm per axis")

    def std_errors(self, sigma_mm: float) -> np.ndarray:
        """(p,) predicted standard errors [mm or deg, see ``units``] of ``parameters`` for a
        noise of ``sigma_mm`` [mm] per axis: sqrt(diag((J_S^T J_S)^-1)) * sigma."""
        return np.sqrt(self.variances) * float(sigma_mm)

    def random_std_errors(self, sigma_mm: float) -> np.ndarray:
        """(p,) the same for random subsets (median variance over the draws)."""
        return np.sqrt(self.random_variances) * float(sigma_mm)

    def summary(self, sigma_mm: float = 0.05, largest: int = 4, checked: str | None = None) -> str:
        """Human report: criterion and condition vs random, largest predicted std errors.

        checked: what the candidates were checked for, when kincal made them (e.g. by
        :func:`kincal.planning.volume_candidates.volume_candidates`)."""
        n, p = len(self.indices), len(self.parameters)
        lines = [f"{self.criterion}-optimal selection of {n} of {self.n_candidates} candidate poses, "
                 f"{self.chain}" + (f", error model {self.model}" if self.model else ""),
                 f"  optimised over the {p} parameters the candidates identify"]
        if self.not_identifiable:
            lines.append(f"  not identifiable from the candidates: {', '.join(self.not_identifiable)}")
        if self.fixed:
            lines.append(f"  fixed by the user: {', '.join(self.fixed)}")
        if self.lost:
            lines.append(f"  WARNING: the chosen poses do not identify {', '.join(self.lost)}")
        gain = self.log_det - self.random_log_det
        lines.append(f"  log det (normalised information): {self.log_det:.2f} chosen, "
                     f"{self.random_log_det:.2f} random median of {self.random_subsets}")
        if math.isfinite(gain):
            lines.append(f"    = {math.exp(gain / p):.3g}x the information per parameter, "
                         f"std errors x{math.exp(-gain / (2 * p)):.3g} (geometric means)")
        lines.append(f"  condition number (information, unit diagonal): {self.condition:.3g} "
                     f"chosen, {self.random_condition:.3g} random median")
        if self.n_targets:
            lines.append(f"  predicted position std over the {self.n_targets} target poses, "
                         f"frame and tool refitted there (RMS per axis, at {sigma_mm:g} mm noise): "
                         f"{math.sqrt(self.mean_variance) * sigma_mm:.4g} mm chosen, "
                         f"{math.sqrt(self.random_mean_variance) * sigma_mm:.4g} mm random median")
        how = "converged" if self.exchange_converged else "stopped at max_swaps"
        lines.append(f"  greedy log det {self.greedy_log_det:.2f}, then {self.swaps} exchanges "
                     f"({how})")
        se, se_r = self.std_errors(sigma_mm), self.random_std_errors(sigma_mm)
        lines.append(f"  largest predicted std errors at a noise of {self.noise_text(sigma_mm)}:")
        lines.append(f"    {'parameter':<22} {'chosen':>10} {'random':>10}  unit")
        for unit in ("mm", "deg"):
            idx = [i for i in range(p) if self.units[i] == unit]
            for i in sorted(idx, key=lambda i: -se[i])[:largest]:
                lines.append(f"    {self.parameters[i]:<22} {se[i]:>10.4g} {se_r[i]:>10.4g}  {unit}")
        lines.append("  (linearised at the nominal robot and tool guess; "
                     + (checked or "the candidates must be safe and measurable, kincal does not "
                        "check") + ")")
        return "\n".join(lines)


def _set_figures(Jn: np.ndarray, scale: np.ndarray, subsets: np.ndarray):
    """(log det, condition, variances [reporting units^2]) of each subset (K, n) of rows."""
    K = len(subsets)
    X = Jn[subsets].reshape(K, -1, Jn.shape[2])
    G = X.transpose(0, 2, 1) @ X
    sign, log_det = np.linalg.slogdet(G)
    d = np.sqrt(np.einsum("kii->ki", G))
    w = np.linalg.eigvalsh(G / (d[:, :, None] * d[:, None, :]))
    ok = w[:, 0] > SINGULAR * w[:, -1]
    # singular by the condition (as the variances are): no finite log det beside them
    log_det = np.where((sign > 0) & ok, log_det, -np.inf)
    cond = np.where(ok, w[:, -1] / np.where(ok, w[:, 0], 1.0), np.inf)
    var = np.full((K, scale.size), np.inf)
    if ok.any():
        var[ok] = np.einsum("kii->ki", np.linalg.inv(G[ok])) / scale ** 2
    return log_det, cond, var


# -------------------------------------------------------------- selection


def _warn_tool_on_axis(model, tool: np.ndarray) -> None:
    """Warn when the tool guess sits on the last revolute axis (its turn is then invisible)."""
    dist = model.last_axis_distance(tool)
    if dist is not None and dist < TOOL_AXIS_WARNING:
        offset, tilt = model.last_axis_parameters()
        sees = f" (and weakly sees {', '.join(tilt)})" if tilt else ""
        warnings.warn(f"the tool point guess is {dist * 1e3:.2f} mm from the axis of "
                      f"{model.joint_names[-1]}: the selection then ignores "
                      f"{', '.join(offset)}{sees}; give the real offset of the measured point "
                      "(tool, --tool-offset)", KincalWarning)


def _check_indices(keep, m: int) -> list[int]:
    out = []
    for k in keep:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k < m:
            raise OptionError(f"keep: {k!r} is not a candidate index (0 to {m - 1})")
        out.append(int(k))
    if len(set(out)) != len(out):
        raise OptionError(f"keep: an index is given twice: {out}")
    return out


def select_poses(robot: "Robot", candidates, n: int, tool=(0.0, 0.0, 0.0), fix=(), keep=(), targets=None,
                 method: str = "D", max_swaps: int = 1000, seed: int = 0,
                 random_subsets: int = RANDOM_SUBSETS,
                 model: str | None = None, kind: str = "point", pivot=None,
                 planes=None) -> PoseSelection:
    """Choose ``n`` of the ``candidates`` to measure (see the module notes).

    candidates: (M, n_joints) joint values in the chain order of ``robot`` [rad or m];
        they must be safe, reachable and measurable, kincal does not check that.
    tool: (3,) guess of the measured point in the tip frame [m]; it decides whether the
        last joint's theta (and alpha) can be seen at all, so give a realistic one.
    fix: parameter names held at nominal (left out of the criterion).
    keep: candidate indices that must be in the selection (e.g. poses already measured).
    method: "D" (maximise log det of the information matrix).
    model: the error model whose parameters the poses should determine (kincal.models;
        None: the chain's default, ``placement`` on a tree path).
    max_swaps: bound on the exchange stage. seed, random_subsets: the random baseline.
    method "I": minimise the mean predicted position variance over ``targets``
        (:mod:`kincal.planning.i_optimal`).
    targets: (T, n_joints) poses where the calibrated robot will work (method "I"; with
        "D" they only add the predicted position std to the report).
    kind: the measurement kind the poses are for ("point", "pose", "distance", "plane":
        :mod:`kincal.measurements.sets`); pivot: (3,) guess of the pivot in the base frame
        [m] (distance); planes: (M,) plane index of each candidate (plane contacts: the
        candidates touch the planes, which are fitted through them).
    """
    if method not in METHODS:
        raise OptionError(f"unknown selection method {method!r}; expected one of {', '.join(METHODS)}")
    g = robot.geometry
    q = np.asarray(candidates, dtype=float)
    if q.ndim != 2 or q.shape[1] != g.n:
        raise DataError(f"candidates must be an (M, {g.n}) array of joint values for "
                        f"{', '.join(g.joint_names)}; got shape {q.shape}")
    bad = np.argwhere(~np.isfinite(q))
    if bad.size:
        r, c = bad[0]
        raise DataError(f"candidate row {r} (0-based) has a non-finite value {q[r, c]} for "
                        f"{g.joint_names[c]}; {len(np.unique(bad[:, 0]))} rows are affected")
    M = len(q)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise OptionError(f"the number of poses must be an integer >= 1, got {n!r}")
    if n > M:
        raise OptionError(f"cannot choose {n} poses from {M} candidates; give more candidates "
                          "or ask for fewer poses")
    keep = _check_indices(keep, M)
    if len(keep) > n:
        raise OptionError(f"keep names {len(keep)} poses, more than the {n} to choose")
    t = np.asarray(tool, dtype=float)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise OptionError(f"tool needs 3 finite numbers (x, y, z in the tip frame) [m], got {tool!r}")
    if not (isinstance(max_swaps, (int, np.integer)) and max_swaps >= 0):
        raise OptionError(f"max_swaps must be an integer >= 0, got {max_swaps!r}")
    if not (isinstance(random_subsets, (int, np.integer)) and random_subsets >= 1):
        raise OptionError(f"random_subsets must be an integer >= 1, got {random_subsets!r}")
    if method == "I" and targets is None:
        raise OptionError("I-optimal selection needs target poses (the volume where the robot "
                          "will work), e.g. --target-cube")
    if targets is not None and kind != "point":
        raise OptionError(f"target poses (I-optimal selection, --target-cube) weigh the "
                          f"predicted tool-point position: they are for --kind point, not "
                          f"{kind!r}")
    if targets is not None:
        targets = np.asarray(targets, dtype=float)
        if targets.ndim != 2 or targets.shape[1] != g.n or len(targets) == 0 \
                or not np.all(np.isfinite(targets)):
            raise DataError(f"targets must be a non-empty (T, {g.n}) array of finite joint "
                            f"values; got shape {targets.shape}")

    if pivot is not None:
        try:
            pv = np.asarray(pivot, dtype=float)
        except (TypeError, ValueError):
            pv = np.full(1, np.nan)
        if pv.shape != (3,) or not np.all(np.isfinite(pv)):
            raise OptionError(f"the pivot needs 3 finite numbers (x, y, z in the base frame) "
                              f"[m] (--pivot), got {pivot!r}" if pv.shape != (3,) else
                              "the pivot needs 3 finite numbers (x, y, z in the base frame) "
                              f"[m] (--pivot), got {' '.join(f'{v:g}' for v in pv)}")
    model = model or error_models.default_for(g)
    em = error_models.build(model, g)
    _warn_tool_on_axis(em, t)
    if kind == "point":
        space = ParameterSpace.of_model(em)
        x = space.join(em.nominal, np.zeros(6), t)
        factor = space.reporting_scale() / MM
        rows_per = 3

        def rows_jacobian_at(poses: np.ndarray) -> np.ndarray:
            """(len(poses), 3, size) in reporting units, for at most BLOCK poses at a time
            (the model's intermediates take ~5x the Jacobian's memory; it costs 3 us per
            pose, so it is made twice instead of held). J^T J does not depend on where the
            measurement frame is: base at the identity."""
            return MeasurementModel(em, poses).jacobian(x)[1] * factor

        def rows_jacobian(rows: np.ndarray) -> np.ndarray:
            return rows_jacobian_at(q[rows])
    else:
        from kincal.measurements.sets import planning_rows

        # equations per pose: 6 (pose), 1 (distance, plane), 3 (flush)
        rows_jacobian, space, rows_per = planning_rows(em, kind, q, t, pivot, planes)
    blocks = [np.arange(s, min(s + BLOCK, M)) for s in range(0, M, BLOCK)]
    free = np.ones(space.size, dtype=bool)
    free[space.indices(fix)] = False  # unknown names raise ParameterError with the list
    # on the triangle of the stacked rows, block by block: no whole Jacobian, no copy of it
    R, m_rows = stacked_triangle((slice(b[0], b[-1] + 1), np.empty(0),
                                  rows_jacobian(b).reshape(-1, space.size)) for b in blocks)
    ident = analyze(R, space.names, space.n_kinematic, free, RANK_TOL, m=m_rows)
    cols = space.indices(ident.kept)
    p = cols.size
    if p == 0:
        raise DataError(f"the {M} candidates identify no parameter at all ({len(ident.free)} "
                        "free): give candidates that move every joint")
    if not np.any(cols < space.n_kinematic) and free[:space.n_kinematic].any():  # joints free
        raise DataError(f"the {M} candidates identify no parameter of the chain's joints, only "
                        f"{', '.join(ident.kept)} (poses that hardly differ?): a plan of them "
                        "calibrates nothing; give candidates that move every joint")
    need = math.ceil(p / rows_per)
    if n < need:
        raise OptionError(f"{n} poses give {rows_per * n} equations, but the candidates identify "
                          f"{p} parameters ({len(ident.free)} free, {len(ident.dropped)} "
                          f"redundant): at least {need} poses are needed ({rows_per} equation(s) "
                          "per pose), and many "
                          "more for a good calibration")
    Jn = np.empty((M, rows_per, p))  # the kept columns, filled block by block
    for b in blocks:
        Jn[b] = rows_jacobian(b)[:, :, cols]
    scale = np.sqrt(sum(np.einsum("kic,kic->c", Jn[b], Jn[b])
                        for b in blocks) / M)  # RMS per pose [mm per mm or deg]
    Jn /= scale

    A = None
    if targets is not None:  # the targets' rows stacked into their triangle, block by block
        Rt, _ = stacked_triangle((slice(s, s + BLOCK), np.empty(0), (rows_jacobian_at(
            targets[s:s + BLOCK])[:, :, cols] / scale).reshape(-1, p))
            for s in range(0, len(targets), BLOCK))
        A = i_optimal.target_moment(Rt[None], space.is_frame[cols], count=len(targets))
    if method == "I":
        assert A is not None  # I-optimal selection has targets (checked above)
        chosen, Minv, ridge = i_optimal.greedy(Jn, n, keep, A)
        greedy_log_det = float(_set_figures(Jn, scale, np.array([chosen]))[0][0])
        chosen, Minv, swaps, converged = i_optimal.exchange(Jn, chosen, len(keep), Minv, A,
                                                            int(max_swaps))
        log_det = -np.inf
    else:
        chosen, Minv, log_det, ridge = _greedy(Jn, n, keep)
        greedy_log_det = log_det if not ridge else -np.inf
        chosen, Minv, log_det, swaps, converged = _exchange(Jn, chosen, len(keep), Minv, log_det,
                                                            int(max_swaps))
    ld, cond, var = _set_figures(Jn, scale, np.array([chosen]))
    if ridge or method == "I":  # report the set's own figures, without the ridge
        log_det = float(ld[0])

    rng = np.random.default_rng(seed)
    rest = np.setdiff1d(np.arange(M), keep)
    draws = np.array([keep + rng.choice(rest, n - len(keep), replace=False).tolist()
                      for _ in range(random_subsets)])
    r_ld, r_cond, r_var = _set_figures(Jn, scale, draws)

    mine = analyze(rows_jacobian(np.asarray(chosen)).reshape(-1, space.size), space.names,
                   space.n_kinematic, free, RANK_TOL)
    lost = tuple(name for name in ident.kept if name not in mine.kept)
    mean_var = r_mean_var = math.nan
    if A is not None:
        mean_var, r_mean_var = (float(np.median(i_optimal.mean_variances(Jn, A, np.array(s))))
                                for s in ([chosen], draws))
    units = tuple("mm" if space.is_length[c] else "deg" for c in cols)
    return PoseSelection(f"{robot.name} ({robot.base} -> {robot.tip})", tuple(g.joint_names), M, tuple(chosen), _readonly(q[chosen]),
                         tuple(ident.kept), units, tuple(ident.dropped), tuple(ident.fixed), lost,
                         _readonly(scale), float(log_det), float(greedy_log_det),
                         float(cond[0]), _readonly(var[0]), swaps, converged,
                         float(np.median(r_ld)), float(np.median(r_cond)),
                         _readonly(np.median(r_var, axis=0)), int(random_subsets),
                         criterion=method, mean_variance=mean_var,
                         random_mean_variance=r_mean_var,
                         n_targets=0 if targets is None else len(targets), kind=kind,
                         model=model)
