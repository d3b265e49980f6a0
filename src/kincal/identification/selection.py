"""What the data can identify: rank, redundant parameters and weak ones.

Plain numpy. Works on the identification Jacobian of the actual data, with columns in
reporting units (mm of position per mm or per degree of parameter), so the analysis
does not depend on SI scaling.

Selection is an ordered rank-revealing QR: columns are taken in a fixed order of
preference and a column is kept when the part of it that the kept columns cannot
reproduce is larger than ``rank_tol`` of its own norm. The order is: measurement frame,
then tool point, then the kinematic parameters from the last joint back to the first
(within a joint in the error model's order: a, alpha, beta, d, theta for MD-H), then any other columns after those (backlash terms).
With several chains the joints come in an order that does not depend on the order the
chains (data files) are given in (:meth:`kincal.identification.chains.Chains.preference`):
each chain's own joints, from its tip back, the chains taken by their (base, tip) names;
then the joints on more than one chain (a humanoid's torso under both arms), deepest in the
URDF tree first. What a shared joint's origin has in common with each chain's own (the
torso's turn against each hip's) is carried by each chain's own, and the shared joint keeps
what only the chains together see. In the union's order (file order, before 2026-12-01)
the first-listed chain's share went to the shared joint and the second chain's to both,
and a mirror-image pair of files calibrated differently in one order and the other.
So a kinematic parameter that duplicates the frame or tool is dropped (not the frame),
of a set of parallel-axis offsets the one nearest the tool is kept, and a backlash term
the data cannot tell from its joint's offset (samples approached from one side) is
dropped, not the offset. This is deterministic (no random draws, no data-dependent
pivoting among equals) and, being greedy in a fixed order, stable as poses are added.

A near-duplicate waits: when the kept set is far worse conditioned than the data
(:data:`POOR_BASIS`), a column kept for a new part much smaller than the weakest direction
the data see (a joint axis along a URDF frame axis only to the rounding of "1.5708") is
taken only after the columns with larger new parts, where it still adds a direction: the
same span, a basis as well conditioned as the data (:func:`_deferring_near_duplicates`).
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, replace

import numpy as np

# Householder R of np.linalg.qr(A, mode="r") (dgeqrf, its numbers) at half numpy's call cost
from kincal.identification.linalg import qr_r

# measurement frame and tool point names; pivot and planes of other measurement kinds, and
# those of further measurement sets (set2.base.x, ...)
_FRAME = re.compile(r"(set\d+\.)?(base|tool\d*|pivot|plane\w*)\.")
RANK_TOL = 1e-7  # relative size of the new part of a column below which it is redundant
WEAK_INDEPENDENCE = 0.02  # kept, but 98 % of its effect reproducible by the others
WEAK_SENSITIVITY = 0.005  # kept, but moves the point less than this [mm RMS per mm or deg]
# a dropped parameter acting like more than this many times a kept one (columns normalised):
# the kept ones' values are combinations (TALOS from its sole 28, serial arms about 1)
AMPLIFIED = 10.0
# a kept set whose (unit-column) condition number exceeds this many times the best the data
# allow for as many columns (the singular values of all the free columns) is a poor basis: a
# column kept for a new part far smaller than every direction the data see (a near-duplicate,
# e.g. a URDF angle written 1.5708 for pi/2) stands in for the later column that carries it
# (serial arms about 1: EC66 complete 14 / 17, placement 8 / 10; TALOS from its sole 84 / 90)
POOR_BASIS = 1e2


@dataclass(frozen=True)
class Duplicate:
    """A dropped parameter and the kept ones that reproduce its effect.

    combination: (name, coefficient) pairs, largest first: one reporting unit of the
    dropped parameter acts like ``coefficient`` units of each named one. Empty when
    the parameter has no effect at all on the measured point. amplification: the largest
    |coefficient| with each column normalised to its effect's size: above
    :data:`AMPLIFIED` the dropped column is the small difference of large kept ones, and a
    small error of the dropped parameter shows as a large correction of the kept ones.
    """

    name: str
    combination: tuple[tuple[str, float], ...]
    amplification: float = 0.0

    def describe(self) -> str:
        if not self.combination:
            return f"{self.name}: no effect on the measured point"
        terms = " ".join(f"{c:+.3g} {n}" for n, c in self.combination)
        return f"{self.name} ~ {terms}"


@dataclass(frozen=True)
class Weak:
    """A kept parameter the data barely constrain.

    independence: fraction (0..1) of its effect the other kept parameters cannot mimic.
    sensitivity: RMS point motion [mm] per unit (mm or deg) of it, after removing what
    the others can mimic.
    """

    name: str
    independence: float
    sensitivity: float
    hint: str = ""
    unit: str = ""  # of the parameter: "mm" or "deg" ("": not known here)

    def describe(self) -> str:
        text = (f"{self.name}: only {100 * self.independence:.2g} % of its effect is its own, "
                f"{self.sensitivity:.3g} mm per {self.unit or 'unit'}")
        return text + (f" ({self.hint})" if self.hint else "")


@dataclass(frozen=True)
class Identifiability:
    """The outcome of :func:`analyze`.

    names: every parameter name; free: those offered to the analysis (not fixed by the
    user); kept / dropped: the partition of ``free``; fixed: fixed by the user.
    rank: numerical rank of the free columns; singular_values: of the free columns,
    each normalised to unit length (descending); condition_number: of the kept columns
    (normalised). duplicates: why each dropped parameter was dropped. weak: kept but
    poorly determined parameters. notes: what else the data mean for the fit; warned:
    those of them also given as warnings (a calibration's summary leaves them out).
    """

    names: tuple[str, ...]
    free: tuple[str, ...]
    kept: tuple[str, ...]
    dropped: tuple[str, ...]
    fixed: tuple[str, ...]
    rank: int
    singular_values: np.ndarray
    condition_number: float
    duplicates: tuple[Duplicate, ...]
    weak: tuple[Weak, ...]
    rank_tol: float
    notes: tuple[str, ...] = ()
    equations: int = 0  # rows of the Jacobian analysed (0: not known)
    warned: tuple[str, ...] = ()

    def in_units(self, is_length: dict) -> "Identifiability":
        """The same, each weak parameter with its unit ("mm" where ``is_length[name]``)."""
        return replace(self, weak=tuple(replace(w, unit="mm" if is_length[w.name] else "deg")
                                        for w in self.weak))

    def headline(self) -> str:
        """The summary's first line: how many parameters the data identify."""
        return (f"identifiable: {len(self.kept)} of {len(self.free)} free parameters "
                f"(rank {self.rank}, condition number {self.condition_number:.3g})")

    def summary(self) -> str:
        lines = [self.headline()]
        if self.fixed:
            lines.append(f"fixed by the user: {', '.join(self.fixed)}")
        spare = no_spare_note(self.equations, len(self.kept)) if self.equations else None
        stand_in = self.stand_in_note()
        lines += [f"note: {n}" for n in (*self.notes, *([spare] if spare else []),
                                          *([stand_in] if stand_in else []))]
        if self.rank != len(self.kept):
            lines.append(f"note: the singular values give rank {self.rank}, the ordered "
                         f"selection kept {len(self.kept)}; parameters near the tolerance "
                         f"{self.rank_tol:g} are borderline")
        for d in self.duplicates:
            lines.append(f"dropped {d.describe()}" + (
                f"  (amplified {d.amplification:.0f}x)" if d.amplification > AMPLIFIED else ""))
        if len(self.weak) <= 6:
            for w in self.weak:
                lines.append(f"weak {w.describe()}")
        else:
            kin = [w for w in self.weak if not _FRAME.match(w.name)]
            worst = sorted(self.weak, key=lambda w: w.independence)[:3]
            lines.append(f"weak: {len(self.weak)} parameters ({len(kin)} kinematic) are barely "
                         "told apart by these poses: " + grouped([w.name for w in self.weak]))
            lines.append("  the poses cover too little of the workspace, or the measurements see "
                         "too little of each pose (a contact fewer directions than a position), "
                         "to separate them; with method l2 they stay near nominal. Weakest: "
                         + "; ".join(w.describe() for w in worst))
        return "\n".join(lines)


    def stand_in_note(self) -> str | None:
        """A note when kept parameters stand in for dropped ones amplified (see Duplicate),
        else None."""
        big = sorted((d for d in self.duplicates if d.amplification > AMPLIFIED),
                     key=lambda d: -d.amplification)
        if not big:
            return None
        return (f"{len(big)} dropped parameters act through kept ones amplified up to "
                f"{big[0].amplification:.0f}x in effect ({big[0].describe()}): those kept "
                "ones' corrections hold such combinations, not their own joints' errors "
                "alone, and single corrected origins there are bookkeeping (the predictions "
                "are the same); kincal analyze (and calibrate -v) lists them")


def grouped(names) -> str:
    """Parameter names with one owner's run written once: "j2.a .d, j3.alpha"."""
    runs: list[list[str]] = []
    for n in names:
        owner, _, part = n.rpartition(".")
        if runs and owner and runs[-1][0] == owner:
            runs[-1].append("." + part)
        else:
            runs.append([owner, n])
    return ", ".join(" ".join(r[1:]) for r in runs)


def no_spare_note(equations: int, identifiable: int) -> str | None:
    """What data that spend every equation on an identifiable parameter mean for a fit
    (None when some are left over): its errors after calibration judge nothing."""
    if equations > identifiable:
        return None
    return (f"{equations} equations for {identifiable} identifiable parameters: none is left "
            "over, so the errors after calibration say nothing of its accuracy (this many "
            "parameters can match any such data that closely); only held-out measurements judge "
            "it (calibrate --validate, kincal evaluate): use it after they do, or measure more "
            "poses")


def preference_order(names, n_kinematic: int, joints=()) -> list[int]:
    """Column indices in the order of preference described in the module notes.

    The first n_kinematic names are ``<joint>.<field>``, grouped by joint in chain order;
    whatever the error model's fields, joints are taken from the last back to the first,
    each joint's fields in the model's order; ``joints`` (several chains): the joints in
    their order of preference instead, any joint it leaves out after them in the default
    order. Made once per layout (three analyses a fit ask for it)."""
    return list(_preference_order(tuple(names), int(n_kinematic), tuple(joints)))


@functools.lru_cache(maxsize=64)
def _preference_order(names: tuple, n_kinematic: int, joints: tuple = ()
                      ) -> tuple[int, ...]:
    frames_end = n_kinematic
    while frames_end < len(names) and _FRAME.match(names[frames_end]):
        frames_end += 1
    order = list(range(n_kinematic, frames_end))  # base then tool point(s)
    groups: dict[str, list[int]] = {}
    for c in range(n_kinematic):
        groups.setdefault(names[c].rsplit(".", 1)[0], []).append(c)
    given = [j for j in joints if j in groups]
    for joint in given + [j for j in reversed(groups) if j not in given]:
        order += groups[joint]
    return tuple(order + list(range(frames_end, len(names))))


def _within_rank(J, norms, names, n_kinematic, free, floor, joints=()) -> tuple[list, list]:
    """(kept, dropped) by the same order of preference, a column kept only while the
    smallest singular value of the kept unit-norm columns stays above ``floor`` (the rank's
    own threshold): never more kept than the rank (by interlacing). The plain ordered
    test compares each new part with its own column, which a run of nearly parallel
    columns (a chain of parallel axes, or frames and origins alike) passes one by one
    although together they span fewer directions: kept > rank, condition number ~1e15."""
    kept: list[int] = []
    dropped: list[int] = []
    for c in preference_order(names, n_kinematic, joints):
        if not free[c]:
            continue
        if norms[c] > 0:
            trial = J[:, kept + [c]] / norms[kept + [c]]
            if np.linalg.svd(trial, compute_uv=False)[-1] > floor:
                kept.append(c)
                continue
        dropped.append(c)
    return sorted(kept), sorted(dropped)


def _ordered(J: np.ndarray, order, free_of, norm_of, rank_tol: float, scale: float
             ) -> tuple[list, list]:
    """(kept, dropped) of the ordered selection (module notes): in the order of preference,
    a free column is kept when its part outside the span of the columns kept before it is
    larger than ``rank_tol`` of its own norm (Python numbers ``norm_of``), dropped when not
    or when its norm is ``rank_tol * scale`` or less.

    Blocked: one Householder QR of the candidates in that order gives each one's part
    outside the span of all before it (the diagonal of R), which is its part outside the
    kept ones' span up to the first column dropped; after a drop the rest go on from their
    rows of R below the kept ones' (their coordinates outside that span), without the
    dropped column, in a QR of that trailing block. So a factorisation per run of drops,
    not a projection per column (the same partition as projecting each column in turn:
    tests/test_fixed_cost.py compares the two)."""
    kept: list = []
    dropped = [c for c in order if free_of[c] and norm_of[c] <= rank_tol * scale]
    cand = [c for c in order if free_of[c] and norm_of[c] > rank_tol * scale]
    lim = [rank_tol * norm_of[c] for c in cand]
    B, at = J[:, cand], 0  # the parts outside the kept span of cand[at:], in coordinates
    while at < len(cand):
        if B.shape[0] == 0:  # the kept columns span every row: nothing else is new
            dropped += cand[at:]
            break
        first = B[:, 0]
        if not math.sqrt(first @ first) > lim[at]:  # a run of drops needs no factorisation
            dropped.append(cand[at])
            B, at = B[:, 1:], at + 1
            continue
        R = qr_r(B)
        d = np.abs(np.diagonal(R)).tolist()
        j = next((t for t, v in enumerate(d) if not v > lim[at + t]), len(d))
        kept += cand[at:at + j]
        at += j
        if at == len(cand):
            break
        if j == len(d):  # as many kept as rows: none left (the loop's first test)
            B = R[j:j, j:]
            continue
        dropped.append(cand[at])
        B, at = R[j:, j + 1:], at + 1  # R's rows j.. (Hessenberg: the dropped column left out)
    kept.sort()
    dropped.sort()
    return kept, dropped


def _select(J: np.ndarray, names, n_kinematic: int, free, rank_tol: float, m: int | None,
            scale: float | None = None, joints=()):
    """The partition of :func:`analyze`: (J or its triangle, names, free, m, column norms,
    kept, dropped, singular values of the free unit columns, rank). scale: the largest
    column norm (default: of these columns); joints: the joints' order of preference
    (several chains, :func:`preference_order`)."""
    names = tuple(names)
    p = len(names)
    free = np.ones(p, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    m = J.shape[0] if m is None else m
    # J = Q R: R has the same column norms, projections and singular values, so all
    # that follows works on p x p numbers whatever the number of poses
    if J.shape[0] > J.shape[1]:
        J = qr_r(J)  # Householder: the rank decision needs full accuracy
    norms = np.linalg.norm(J, axis=0)
    if scale is None:
        scale = float(norms.max()) if norms.size else 1.0
    order = preference_order(names, n_kinematic, joints)
    kept, dropped = _ordered(J, order, free.tolist(), norms.tolist(), rank_tol, scale)
    free_idx = np.flatnonzero(free)
    Jn = J[:, free_idx] / np.where(norms[free_idx] > 0, norms[free_idx], 1.0)
    sv = np.linalg.svd(Jn, compute_uv=False) if free_idx.size else np.zeros(0)
    rank = int(np.sum(sv > rank_tol * sv[0])) if sv.size else 0
    if kept and rank:
        kept, dropped = _deferring_near_duplicates(J, norms, order, free.tolist(), rank_tol,
                                                   scale, sv, rank, kept, dropped)
    if len(kept) > rank:  # many nearly parallel columns: each new part passes, the set not
        kept, dropped = _within_rank(J, norms, names, n_kinematic, free, rank_tol * sv[0],
                                     joints)
    return J, names, free, m, norms, kept, dropped, sv, rank


def _condition(J: np.ndarray, norms: np.ndarray, cols: list) -> float:
    """Condition number of the columns ``cols`` of J, each scaled to unit norm."""
    s = np.linalg.svd(J[:, cols] / norms[cols], compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def _deferring_near_duplicates(J, norms, order, free_of, rank_tol, scale, sv, rank, kept,
                               dropped) -> tuple[list, list]:
    """(kept, dropped) of the ordered selection, made again when it kept a poor basis (see
    :data:`POOR_BASIS`): a column whose new part is below a fraction (1/1000, else 1/100, else
    1/10) of the weakest direction the data see (the singular values ``sv`` of the free unit
    columns, as many as kept) waits, the columns with larger new parts are taken first in
    the order of preference, then the waiting ones in that order where they still add a
    direction (``rank_tol``); the first fraction that gives a set no longer poor is used
    (else the best conditioned, if better than the first). Why: one kept near-duplicate (a
    new part of 3e-6 of its norm, when a joint axis is a URDF frame axis only to the
    rounding of "1.5708") makes the later column that carries that direction look
    redundant; the kept set is then ~1e6 times worse conditioned than the data, and every
    dropped parameter it stands in for needs corrections ~1e6 times its size (a fit from
    nominal then stops far from the minimum: 0.1 mm on noise-free EC66 data, placement
    model). The same span, and the same partition whenever the first one is not poor; data
    whose weakest direction is itself near ``rank_tol`` (a small measurement volume: no
    fraction of it is above the tolerance) keep the first."""
    k = min(len(kept), rank)
    weakest = float(sv[k - 1] / sv[0])
    worst = POOR_BASIS / weakest
    best, best_cond = (kept, dropped), _condition(J, norms, kept)
    if best_cond <= worst:
        return kept, dropped
    norm_of = norms.tolist()
    for fraction in (1e-3, 1e-2, 1e-1):
        if weakest * fraction <= rank_tol:
            continue
        strong, _ = _ordered(J, order, free_of, norm_of, weakest * fraction, scale)
        first = set(strong)
        again = _ordered(J, [c for c in order if c in first] + [c for c in order
                                                                if c not in first],
                         free_of, norm_of, rank_tol, scale)
        if len(again[0]) < k:
            continue
        cond = _condition(J, norms, again[0])
        if cond < best_cond:
            best, best_cond = again, cond
        if cond <= worst:
            break
    return best


def identifiable(J: np.ndarray, names, n_kinematic: int, free=None,
                 rank_tol: float = RANK_TOL, m: int | None = None, joints=()
                 ) -> tuple[str, ...]:
    """The names :func:`analyze` keeps, without its report (why each dropped one was
    dropped, weak ones, condition number): for a caller that needs only the partition (the
    frame start's, three analyses per fit). Of the free columns alone when some are not
    free (the frame start's: its kinematic columns are held): the order of preference, the
    projections and the rank decision the same among them, the scale of every column."""
    if free is not None and not np.all(free) and J.shape[0] > J.shape[1]:
        idx = np.flatnonzero(free)
        norms = np.linalg.norm(J, axis=0)
        return _identifiable_of(J[:, idx], tuple(names[i] for i in idx),
                               int(np.sum(idx < n_kinematic)), rank_tol, m,
                               float(norms.max()) if norms.size else 1.0, joints=joints)
    return _identifiable_of(J, names, n_kinematic, rank_tol, m, None, free, joints)


def _identifiable_of(J, names, n_kinematic, rank_tol, m, scale, free=None, joints=()
                     ) -> tuple[str, ...]:
    """:func:`identifiable` of these columns, the largest column norm ``scale`` (None: theirs)."""
    _, names, _, _, _, kept, _, _, _ = _select(J, names, n_kinematic, free, rank_tol, m, scale,
                                               joints)
    return tuple(names[i] for i in kept)


def analyze(J: np.ndarray, names, n_kinematic: int, free=None, rank_tol: float = RANK_TOL,
            weak_independence: float = WEAK_INDEPENDENCE,
            weak_sensitivity: float = WEAK_SENSITIVITY, m: int | None = None,
            samples: int | None = None, joints=()) -> Identifiability:
    """Identifiability of the parameters from a Jacobian in reporting units.

    J: (m, p) rows = residual components [mm], columns = parameters [mm or deg]; or the
    triangle R (p, p) of its QR factorisation, with its number of rows ``m`` given.
    free: (p,) bool, the parameters the user did not fix (default: all).
    samples: the samples the rows belong to, over which a weak parameter's sensitivity is
    an RMS (a pose's 6 rows, a distance's 1); None: m / 3 where m is a multiple of 3
    (measured points), else m. joints: the joints' order of preference (several chains;
    module notes), () for the default.
    """
    J, names, free, m, norms, kept, dropped, sv, rank = _select(J, names, n_kinematic, free,
                                                                rank_tol, m, joints=joints)
    p = len(names)
    rows = samples if samples else m // 3 if m % 3 == 0 else m  # samples, for RMS figures
    scale = float(norms.max()) if norms.size else 1.0
    free_idx = np.flatnonzero(free)
    Jk = J[:, kept]
    Jkn = Jk / norms[kept]
    svk = np.linalg.svd(Jkn, compute_uv=False)
    cond = float(svk[0] / svk[-1]) if svk.size and svk[-1] > 0 else float("inf")
    duplicates = []
    norm_of = norms.tolist()
    seen = [c for c in dropped if norm_of[c] > rank_tol * scale]
    # every dropped column against the kept ones in one solve (one SVD of Jk), the four
    # largest of each row in one argsort (row by row: the order each row's own gives);
    # coefficients equal to 9 decimals are tied and keep the kept columns' order, so the
    # rounding of the solve (the whole J, or the triangle of J streamed in blocks) does
    # not reorder a parameter's equals (joint_1.alpha ~ -1 plane1.rx -1 plane2.rx ...)
    coefs: dict = {}
    if seen:
        C = np.linalg.lstsq(Jk, J[:, seen], rcond=None)[0].T
        big4 = np.argsort(-np.round(np.abs(C), 9), axis=1, kind="stable")[:, :4]
        coefs = dict(zip(seen, zip(C.tolist(), big4.tolist())))
    for c in dropped:  # Python numbers read once (the same values: float of each element)
        if c not in coefs:
            duplicates.append(Duplicate(names[c], ()))
            continue
        coef, big = coefs[c]
        top = [(names[kept[i]], coef[i]) for i in big if abs(coef[i]) >= 0.05 * abs(coef[big[0]])]
        gain = max(abs(coef[i]) * norm_of[kept[i]] for i in range(len(kept))) / norm_of[c]
        duplicates.append(Duplicate(names[c], tuple(top), gain))
    weak = []
    if kept:
        G = Jkn.T @ Jkn
        Ginv = np.linalg.pinv(G)
        independence = 1.0 / np.sqrt(np.maximum(np.diag(Ginv), 1e-300))
        sensitivity = independence * norms[kept] / np.sqrt(max(rows, 1))
        for c, ind, sen in zip(kept, independence.tolist(), sensitivity.tolist()):
            if ind < weak_independence or sen < weak_sensitivity:
                weak.append(Weak(names[c], ind, sen))
    return Identifiability(names, tuple(names[i] for i in free_idx), tuple(names[i] for i in kept),
                           tuple(names[i] for i in dropped),
                           tuple(names[i] for i in range(p) if not free[i]), rank, sv, cond,
                           tuple(duplicates), tuple(weak), rank_tol, equations=m)
