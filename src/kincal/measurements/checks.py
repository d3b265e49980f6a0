"""Sanity checks of measurement data against the robot, before any fitting.

Plain numpy. Each check returns human messages (for KincalWarning) naming the joint,
the line of the file and the expected range; none of them alters a sample.
"""

from __future__ import annotations

import numpy as np

from kincal.errors import DataError

UNIT_RATIO = 30.0  # measured spread this many times the robot's: probably mm read as m
DEGREES_AS_RADIANS = 2 * np.pi + 0.5  # [rad] a revolute value beyond: probably degrees


def _farthest_beyond(q: np.ndarray, lo: np.ndarray, hi: np.ndarray, mask: np.ndarray):
    """(row, joint, signs) of the farthest value from zero among those of ``mask`` outside
    their limits [lo, hi] (the data's limit slack, 1e-6), with every such value's sign
    (N, n); None when there is none: the evidence a unit clue names."""
    sign = mask & ((q < lo - 1e-6) | (q > hi + 1e-6))
    if not sign.any():
        return None
    i, j = np.unravel_index(np.argmax(np.where(sign, np.abs(q), -1.0)), q.shape)
    return int(i), int(j), sign


def degrees_read_as_radians(joint_names, kinds, lower, upper, q, rows) -> str:
    """"" or what shows that revolute values in radians were degrees: a joint with limits
    beyond them and beyond a turn and a half (DEGREES_AS_RADIANS), the farthest such value
    named with its line. A value within a turn is no sign (the limits may be wrong)."""
    q = np.asarray(q, dtype=float)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    bounded = np.array([k == "revolute" for k in kinds]) & (np.isfinite(lo) | np.isfinite(hi))
    found = _farthest_beyond(q, lo, hi, (np.abs(q) > DEGREES_AS_RADIANS) & bounded)
    if found is None:
        return ""
    i, j, sign = found
    return (f"{joint_names[j]} is {q[i, j]:.4g} rad ({q[i, j] / np.pi:.1f} pi) at line "
            f"{rows[i]}, outside its URDF limits [{lo[j]:.4g}, {hi[j]:.4g}] rad "
            f"({int(sign.any(axis=1).sum())} of {len(q)} rows have such values): were the "
            "joint values degrees? Read them with --angle-unit deg (Python: angle_unit='deg')")


def millimetres_read_as_metres(joint_names, kinds, lower, upper, q, rows) -> str:
    """"" or what shows that prismatic values read in metres were millimetres: a prismatic
    joint with limits, a value beyond them and more than UNIT_RATIO times its farthest limit
    from zero (or its travel, if larger), the farthest such value named with its line. (A
    pose file logged in mm and degrees with a prismatic joint, as the TIAGo's torso: its
    lengths grow with the positions, so the positions' spread gives no clue.)"""
    q = np.asarray(q, dtype=float)
    lo, hi = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    with np.errstate(invalid="ignore"):
        scale = np.maximum(np.maximum(np.abs(lo), np.abs(hi)), hi - lo)
    scale = np.where(np.isfinite(scale) & (scale > 0), scale, np.inf)
    prismatic = np.array([k == "prismatic" for k in kinds], dtype=bool)
    found = _farthest_beyond(q, lo, hi, prismatic & (np.abs(q) > UNIT_RATIO * scale))
    if found is None:
        return ""
    i, j, _ = found
    return (f"{joint_names[j]} is {q[i, j]:.4g} m at line {rows[i]}, {abs(q[i, j]) / scale[j]:.0f} "
            f"times the farthest of its URDF limits [{lo[j]:.4g}, {hi[j]:.4g}] m")


LIMIT_JOINTS_LISTED = 3  # joints outside their limits named one warning each; beyond, one


def limit_warnings(joint_names, kinds, lower, upper, q, rows) -> list[str]:
    """Joint values outside the URDF limits (1e-6 of slack for rounding): a warning per joint,
    or, when more than LIMIT_JOINTS_LISTED joints are outside (a unit or a column order that
    does not fit the file, not one bad sample), one warning naming the worst of them."""
    out, excess_of = [], []
    outside = (q < np.asarray(lower) - 1e-6) | (q > np.asarray(upper) + 1e-6)
    for j in np.flatnonzero(outside.any(axis=0)).tolist():  # every joint in one test first
        name, lo, hi = joint_names[j], lower[j], upper[j]
        bad = np.flatnonzero(outside[:, j])
        excess = np.maximum(lo - q[bad, j], q[bad, j] - hi)
        k = bad[np.argmax(excess)]
        unit = "m" if kinds[j] == "prismatic" else "rad"
        out.append(f"{name}: {bad.size} of {len(q)} values outside its URDF limits "
                   f"[{lo:.4g}, {hi:.4g}] {unit} (worst {q[k, j]:.4g} at line {rows[k]})")
        excess_of.append(float(excess.max()) / (hi - lo if np.isfinite(hi - lo) and hi > lo
                                                else 1.0))
    if len(out) <= LIMIT_JOINTS_LISTED:
        return out
    worst = np.argsort(excess_of)[::-1][:LIMIT_JOINTS_LISTED]
    return [f"{len(out)} of {len(joint_names)} chain joints have values outside their URDF "
            f"limits, farthest beyond their range: "
            + "; ".join(out[i] for i in sorted(worst.tolist()))
            + f"; and {len(out) - LIMIT_JOINTS_LISTED} more joints"]


def angle_unit_warnings(joint_names, kinds, q, angle_unit: str, lower=None,
                        upper=None) -> list[str]:
    """Revolute values that look like degrees read as radians, or the reverse. With the
    joints' limits (lower, upper), large values of a continuous joint (no limits: it may
    turn many times) are no sign of degrees."""
    rev = [j for j, k in enumerate(kinds) if k == "revolute"]
    if not rev:
        return []
    bounded = rev if lower is None or upper is None else [
        j for j in rev if np.isfinite(lower[j]) or np.isfinite(upper[j])]
    biggest = float(np.max(np.abs(q[:, bounded]))) if bounded else 0.0
    if angle_unit == "rad" and biggest > DEGREES_AS_RADIANS:
        return [f"revolute joint values reach {biggest:.4g} rad ({biggest / np.pi:.1f} pi): were "
                "they degrees? Read them with --angle-unit deg (Python: angle_unit='deg')"]
    if angle_unit != "deg":
        return []
    if bounded and biggest <= np.radians(DEGREES_AS_RADIANS):  # as read: within +-6.8 "deg"
        return [f"revolute joint values all lie within +-{np.degrees(biggest):.3g} deg of zero, "
                "as radians would read as degrees: were they radians? Drop --angle-unit deg"]
    if len(q) <= 3:
        return []
    spans = np.ptp(q[:, rev], axis=0)
    if float(spans.max()) < np.radians(3.0):
        return [f"revolute joint values span at most {np.degrees(spans.max()):.3g} deg: were they "
                "radians read as degrees? Drop --angle-unit deg"]
    return []


def spread(points: np.ndarray) -> float:
    """RMS distance [m] of points from their centroid."""
    return float(np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))


def distance_ratio(distances: np.ndarray, points: np.ndarray) -> float:
    """The range of measured distances (N,) [m] over the widest range the tool points (N, 3)
    [m] allow them (twice their largest distance from their centroid: a distance to a fixed
    pivot changes by no more than the point moves), when above 1 (NaN otherwise: a narrow
    range is no clue, a point moving on a sphere about the pivot keeps one distance)."""
    reach = 2.0 * float(np.sqrt(np.max(np.sum((points - points.mean(axis=0)) ** 2, axis=1))))
    r = float(np.ptp(distances)) / reach if reach >= 1e-3 else float("nan")
    return r if r > 1.0 else float("nan")


def length_unit_warnings(measured: np.ndarray, predicted: np.ndarray, length_unit: str) -> list[str]:
    """Measured positions far larger or smaller than what the robot's motion can produce."""
    s_meas, s_pred = spread(measured), spread(predicted)
    if s_pred < 1e-3 or len(measured) < 3:  # the poses barely differ: nothing to compare
        return []
    ratio = s_meas / s_pred
    if ratio > UNIT_RATIO:
        return [f"measured positions spread {s_meas:.4g} m while the robot's tip moves by "
                f"{s_pred:.3g} m: were they millimetres? Read them with --length-unit mm"]
    if ratio < 1.0 / (10 * UNIT_RATIO) and length_unit == "mm":
        return [f"measured positions spread only {s_meas * 1e3:.3g} mm while the robot's tip "
                f"moves by {s_pred * 1e3:.3g} mm: were they metres read as millimetres?"]
    if ratio < 1.0 / (10 * UNIT_RATIO):
        return [f"measured positions spread only {s_meas * 1e3:.3g} mm while the robot's tip "
                f"moves by {s_pred * 1e3:.3g} mm: check the units and that the positions match "
                "the joint values"]
    return []


def unit_warnings(km, tool_guess=None) -> list[str]:
    """A kind model's measured positions about 1000x larger or smaller than its nominal
    motion (mm read as m), each message naming the file; none for kinds without positions.
    tool_guess: the tool point on the tip (--tool-offset) [m], default the tip's origin."""
    d = km.data
    if getattr(d, "positions", None) is None:
        return []
    first = np.ones(len(d), bool) if getattr(d, "points", None) is None else d.points == 0
    guess = np.zeros(3) if tool_guess is None else np.asarray(tool_guess, float)
    tips = km.chain.tip_point(km.error_model.nominal, guess)  # in blocks: no (N, 3, 3)
    return [f"{d.source}: {m}" for m in length_unit_warnings(
        d.positions[first], tips[first], getattr(d, "length_unit", "m"))]


def distinct_poses(q: np.ndarray) -> int:
    """Number of distinct joint configurations (to 1e-9)."""
    return int(np.unique(np.round(q, 9), axis=0).shape[0])


TOOL_RATIO = 3.0  # a tool point farther from the tip than this many chain lengths: a unit slip


def tool_unit_warnings(error_model, tool_guess) -> list[str]:
    """A tool point guess [m] farther from the tip frame than TOOL_RATIO times the chain's
    length: millimetres given as metres (a contact set has no positions to tell it by; the
    gate then refuses the lever arm's motion, not naming the cause)."""
    if tool_guess is None:
        return []
    from kincal.models.geometry import chain_length

    em = error_model
    frames = em.joint_frames()  # the tip frame at zero joint values, from the last placed frame
    length = chain_length(frames, frames[-1] @ np.linalg.inv(em.joint_offsets[-1]) @ em.T_last_tip)
    far = float(np.linalg.norm(tool_guess))
    if far <= TOOL_RATIO * length:
        return []
    return [f"the tool point guess (--tool-offset) lies {far:.4g} m from the tip frame, "
            f"{far / length:.0f} times the chain's length ({length:.3g} m): were its values "
            "millimetres? --tool-offset is in the data's --length-unit"]


def warn_units(kinds, tool_guess=None) -> None:
    """Warn (:class:`~kincal.errors.KincalWarning`) :func:`unit_warnings` of each kind model
    and :func:`tool_unit_warnings` of each chain: a fit's start does, and so does a problem
    evaluated without a fit (evaluate --frames)."""
    import warnings

    from kincal.errors import KincalWarning

    messages = []
    for km in kinds:
        messages += unit_warnings(km, tool_guess) + tool_unit_warnings(km.error_model, tool_guess)
    for message in dict.fromkeys(messages):
        warnings.warn(message, KincalWarning)


def set_warnings(data, geometry, backlash=()) -> list[str]:
    """The warnings of one measurement set against the chain: joint values outside the URDF
    limits or in the wrong angle unit (one sample per pose), and backlash joints whose
    samples do not come from both directions, or whose order ignores a time-like column."""
    import re

    pose = np.unique(data.poses, return_index=True)[1]
    q = data.joint_values[pose]
    g = geometry
    mm = ("" if getattr(data, "length_unit", "m") != "m" else  # first: the causes the
          millimetres_read_as_metres(g.joint_names, g.kinds, g.lower, g.upper, q,  # limits
                                     data.rows[pose]))                              # show
    out = ([f"{mm}: were the lengths millimetres? Read them with --length-unit mm (Python: "
            "length_unit='mm')"] if mm else [])
    out += (angle_unit_warnings(g.joint_names, g.kinds, q, getattr(data, "angle_unit", "rad"),
                                g.lower, g.upper)
           + limit_warnings(g.joint_names, g.kinds, g.lower, g.upper, q, data.rows[pose]))
    order = getattr(data, "order_source", "the order of the rows")
    timelike = [c for c in data.ignored_columns
                if re.search(r"time|stamp|(^|_)t($|_)", c, re.IGNORECASE)]
    if backlash and not getattr(data, "has_order_column", False) and timelike:
        out.append(f"backlash: the approach directions come from {order}; "
                   f"the file has a column {timelike[0]!r} that looks like a time stamp: if "
                   f"the rows are not in acquisition order, give it as the order column "
                   f"(--order-column {timelike[0]})")
    for j in backlash:
        a = data.approach[:, list(g.joint_names).index(j)]
        up, down = int(np.sum(a > 0)), int(np.sum(a < 0))
        if min(up, down) < 3:
            out.append(f"{j}.backlash: {up} samples approached {j} from below and {down} "
                       f"from above (acquisition order: {order}); "
                       "backlash is identifiable only from both directions, a few of "
                       "each at least")
    return out


# [m] the stated standard deviations kincal accepts, 1 nm to 1 m: outside, a unit slip or a
# placeholder, and weights 1 / sigma^2 that under- or overflow (or drown whole sets)
SIGMA_RANGE_M = (1e-9, 1.0)
# [deg] likewise for orientation sigmas: below, orientation rows would drown the positions
SIGMA_RANGE_DEG = (1e-6, 90.0)


def check_sigmas(values, n: int, source: str, what: str = "sigma", unit: str = "m",
                 rows=None) -> np.ndarray:
    """(n,) stated standard deviations as a read-only array; DataError naming the first
    value outside SIGMA_RANGE_M (unit "m") or SIGMA_RANGE_DEG (unit "deg"), and the range.
    rows: (n,) file line numbers for the message, or None."""
    lo, hi = SIGMA_RANGE_M if unit == "m" else SIGMA_RANGE_DEG
    try:
        s = np.array(values, dtype=float)
        s.setflags(write=False)
    except (TypeError, ValueError):
        raise DataError(f"{source}: {what} must be {n} numbers, got {values!r}") from None
    if s.shape != (n,):
        raise DataError(f"{source}: {what} must be {n} values, got shape {s.shape}")
    bad = np.flatnonzero(~(np.isfinite(s) & (s >= lo) & (s <= hi)))
    if bad.size:
        k = int(bad[0])
        where = f"line {rows[k]}" if rows is not None else f"sample {k + 1}"
        shown = (f"{s[k] * 1e3:g} mm" if unit == "m" else f"{s[k]:g} deg")
        limits = (f"{lo * 1e3:g} mm to {hi * 1e3:g} mm" if unit == "m" else
                  f"{lo:g} deg to {hi:g} deg")
        raise DataError(f"{source}: {where}: {what} {shown} is outside the accepted range "
                        f"{limits} (a standard deviation of the measurement)")
    return s


def _sample_parts(data) -> list[np.ndarray]:
    """Every per-sample number of a set (its ``per_sample_fields``), as (N, k_i) float
    arrays: joint values, what was measured, its sigmas, its point or plane index; not the
    line numbers, poses or approach directions, which differ between copies."""
    n = len(data.joint_values)
    return [np.asarray(v, dtype=float).reshape(n, -1) for name in data.per_sample_fields()
            if name not in ("rows", "poses", "approach")
            for v in [getattr(data, name)] if v is not None]


def _sample_rows(data, index: np.ndarray) -> np.ndarray:
    """(len(index), k) the samples ``index`` of a set, every number of each
    (:func:`_sample_parts`) as one void key (exact copies alike, -0.0 apart from 0.0)."""
    rows = np.ascontiguousarray(np.hstack([part[index] for part in _sample_parts(data)]))
    return rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1])))[:, 0]


# what a sample repeated exactly does to a calibration (the note kincal adds to the finding)
DUPLICATE_WHY = ("a copy counts as a second measurement, weighs twice and makes the noise "
                 "look smaller than it is; remove the copies (a true repeat differs at least "
                 "in the last digits of its readings)")

_MIX = np.uint64(0x9E3779B97F4A7C15)  # odd multiplier of the hash (Fibonacci hashing)


def _sample_keys(data) -> tuple[np.ndarray, int]:
    """((N,) uint64 hash of each sample's numbers bit for bit, the count of numbers per
    sample). Made a column at a time: 8 bytes per sample, where the samples' rows as keys
    (and the sorts of them) took about 350 traced, on top of the fit's peak
    (the gate runs this). Equal samples have equal hashes; samples whose hashes match are
    compared exactly (:func:`_sample_rows`), so a collision never makes a finding."""
    parts = _sample_parts(data)
    h = np.zeros(len(data.joint_values), dtype=np.uint64)
    for part in parts:
        for c in range(part.shape[1]):
            h ^= np.ascontiguousarray(part[:, c]).view(np.uint64)
            h *= _MIX
            h ^= h >> np.uint64(29)
    return h, sum(part.shape[1] for part in parts)


def _lines(data, n: int) -> np.ndarray:
    return data.rows if data.rows is not None else np.arange(n) + 2


def _matches(data, other, keys, other_keys) -> tuple[np.ndarray, np.ndarray]:
    """(indices of the samples of ``data`` that repeat one of ``other`` exactly, the index
    in ``other`` of the first sample each repeats)."""
    (h, width), (oh, other_width) = keys, other_keys
    if width != other_width:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    mine = np.flatnonzero(np.isin(h, oh))  # hashes shared: candidates, compared exactly
    theirs = np.flatnonzero(np.isin(oh, h[mine]))
    a, b = _sample_rows(data, mine), _sample_rows(other, theirs)
    distinct, first = np.unique(b, return_index=True)  # the first sample of each value
    found = np.isin(a, distinct)
    return mine[found], theirs[first[np.searchsorted(distinct, a[found])]]


def repeated_samples(data, other, keys=None, other_keys=None) -> str | None:
    """The finding when samples of ``data`` repeat samples of ``other`` exactly (a set of
    the same kind and joints; every joint value and reading to the last digit), else None."""
    keys = _sample_keys(data) if keys is None else keys
    other_keys = _sample_keys(other) if other_keys is None else other_keys
    if type(other) is not type(data) or other.joint_names != data.joint_names:
        return None
    both, first = _matches(data, other, keys, other_keys)
    if not both.size:
        return None
    n, n_other = len(keys[0]), len(other_keys[0])
    return (f"{data.source}: {both.size} of its {n} samples repeat samples of "
            f"{other.source} exactly (line {_lines(data, n)[both[0]]} = line "
            f"{_lines(other, n_other)[first[0]]} there: the same data given twice?)")


def repeats_all(data, other) -> bool:
    """Whether every sample of ``data`` repeats a sample of ``other`` exactly."""
    keys = _sample_keys(data)
    both, _ = _matches(data, other, keys, _sample_keys(other))
    return both.size == len(keys[0])


def duplicate_samples(sets) -> list[str]:
    """Samples that repeat another exactly (every joint value and every reading to the last
    digit), in one set or across sets of one kind, one finding per set that has them
    (:data:`DUPLICATE_WHY` says what they do)."""
    out: list[str] = []
    seen: list[tuple] = []  # (set, its sample keys)
    for data in sets:
        keys = _sample_keys(data)
        h = keys[0]
        lines = _lines(data, len(h))
        order = np.argsort(h, kind="stable")  # samples whose hash another shares: compared
        same = h[order[1:]] == h[order[:-1]]
        shared = np.zeros(len(h), dtype=bool)
        shared[1:] |= same
        shared[:-1] |= same
        candidates = np.sort(order[shared])
        del order, same, shared
        if candidates.size:
            rows = _sample_rows(data, candidates)
            _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
            earliest = first[inverse.ravel()]  # each candidate's first occurrence
            copies = np.flatnonzero(earliest != np.arange(len(candidates)))
            if copies.size:
                k = int(copies[0])
                out.append(f"{data.source}: {copies.size} sample(s) repeat earlier ones "
                           f"exactly (line {lines[candidates[k]]} repeats line "
                           f"{lines[candidates[earliest[k]]]})")
        for other, other_keys in seen:
            found = repeated_samples(data, other, keys, other_keys)
            if found:
                out.append(found)
                break
        seen.append((data, keys))
    return out


def input_warnings(sets, robots, backlash=()) -> list[str]:
    """Every set's :func:`set_warnings` against its robot's chain (``backlash``: the joints
    with a backlash term, those on the chain checked), each prefixed with its source. (The
    :func:`duplicate_samples` go through the plausibility gate: a note with the files it
    lets through, the likely cause in a refusal's one line.)"""
    out = []
    for data, r in zip(sets, robots):
        back = [j for j in backlash if j in r.joint_names]
        out += [f"{data.source}: {m}" for m in set_warnings(data, r.geometry, back)]
    return out
