"""Error models: how geometric errors of the chain are parametrised, one module each.

| name | parameters per joint | suits |
|---|---|---|
| ``complete`` (default) | MD-H ``.a .alpha .d .theta`` + ``.beta`` at nearly parallel axes | every serial arm: complete, continuous, minimal after selection |
| ``mdh`` | ``.a .alpha .d .theta`` (Craig's modified DH) | the seed paper's reproduction; arms without parallel axes |
| ``placement`` | ``.tx .ty .tz .rx .ry .rz`` of the URDF origin | reading corrections as URDF origin changes (FIGAROH's model); tree paths |
| ``offsets`` | ``.theta`` (``.d`` if prismatic) | re-mastering: joint zeros only, few poses |

Tree paths (a base anywhere in the URDF tree, joints on the way up reversed; see
:mod:`kincal.robot`): ``placement`` and ``offsets`` describe them (each correction is one
of a traversed URDF origin); ``complete`` and ``mdh`` refuse them (OptionError), their
first row would move the first axis within the base frame's own link.

All share the interface of :mod:`kincal.models.base`, the chain engine of
:mod:`kincal.models.chain`, and everything downstream (selection, penalty, solver,
export). :func:`build` makes one by name.
"""

from __future__ import annotations

import threading

from kincal.errors import OptionError

MODELS = ("complete", "mdh", "placement", "offsets")
DEFAULT = "complete"
SUITS = {
    "complete": "MD-H + Hayati's beta at nearly parallel axes: complete and continuous (default)",
    "mdh": "Craig's modified DH, 4 per joint: the seed paper's model; misses tilts of parallel axes",
    "placement": "6 errors per URDF joint origin (FIGAROH's full model): complete, redundancy "
                 "removed by the selection; suits tree paths (a base anywhere in the tree)",
    "offsets": "joint zeros only (re-mastering): few parameters, no link or axis corrections; "
               "suits tree paths",
}


def default_for(geometry) -> str:
    """The default model for a chain: DEFAULT, or "placement" on a tree path (a base off the
    tip's branch), which the MD-H models cannot describe."""
    rev = getattr(geometry, "reversed", None)
    return "placement" if rev is not None and any(rev) else DEFAULT


_MEMO: dict = {}  # (what, id(geometry)) -> (geometry, value): per robot, the last few
_MEMO_MAX = 64
_LOCK = threading.Lock()


def per_geometry(what, geometry, make):
    """``make()``, computed once per (``what``, geometry object) and shared after: the one
    home of what kincal keeps per robot between fits. A Robot is never modified (its
    corrected copies are new Robots with geometries of their own), so what depends only on
    a geometry is the same at every fit of that robot. The entry holds the geometry, so its
    id is not reused while the entry lives; the least recently used entries go first."""
    key = (what, id(geometry))
    with _LOCK:  # fits in threads (kincal fleet) share it
        hit = _MEMO.pop(key, None)
        if hit is not None and hit[0] is geometry:
            _MEMO[key] = hit  # the most recently used go last: a robot's entries stay while
            return hit[1]  #    one-off geometries (each fit's corrected robot) come and go
    value = make()
    with _LOCK:
        while len(_MEMO) >= _MEMO_MAX:
            _MEMO.pop(next(iter(_MEMO)))
        _MEMO[key] = (geometry, value)
    return value


def build(name: str, geometry):
    """The error model ``name`` (one of MODELS) of a :class:`kincal.models.geometry.ChainGeometry`.

    Built once per geometry (:func:`per_geometry`): every fit of one robot shares its
    models (building the complete model costs ~1.3 ms, a tenth of a 60-pose fit). The
    models are frozen and their arrays read-only, so no user of a shared one changes it."""
    return per_geometry(("model", name), geometry, lambda: _read_only(_build(name, geometry)))


def _read_only(model):
    for value in vars(model).values():
        flags = getattr(value, "flags", None)  # numpy arrays (numpy not imported here)
        if flags is not None:
            flags.writeable = False
    return model


def _build(name: str, geometry):
    if name == "complete":
        from kincal.models import complete
        return complete.build(geometry)
    if name == "mdh":
        from kincal.models import mdh
        return mdh.extract(geometry)
    if name == "placement":
        from kincal.models import placement
        return placement.build(geometry)
    if name == "offsets":
        from kincal.models import offsets
        return offsets.build(geometry)
    raise OptionError(f"unknown error model {name!r}; expected one of {', '.join(MODELS)} ("
                      + "; ".join(f"{k}: {v}" for k, v in SUITS.items()) + ")")


__all__ = ["MODELS", "DEFAULT", "SUITS", "build", "default_for"]
