"""Names, units and layout of the calibration parameters.

The parameter vector x holds absolute values (not errors), in SI units:

    [ <joint_1>.a, .alpha, .d, .theta, ..., <joint_n>.theta,      4 n kinematic (MD-H)
      base.x, base.y, base.z, base.rx, base.ry, base.rz,          measurement frame
      tool.x, tool.y, tool.z ]                                     tool point in the tip frame

The measurement frame M sees the tool point at
``P = R_base (p_tip + R_tip t_tool) + t_base`` with ``R_base = Rx(rx) Ry(ry) Rz(rz)``.
Lengths are in metres, angles in radians; reports convert to mm and degrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import ParameterError, listing, suggest
from .mdh import FIELDS, LENGTH_FIELDS

BASE = ("base.x", "base.y", "base.z", "base.rx", "base.ry", "base.rz")
TOOL = ("tool.x", "tool.y", "tool.z")
MM = 1e-3  # [m]
DEG = math.pi / 180.0  # [rad]


@dataclass(frozen=True)
class ParameterSpace:
    """The parameters of one chain: stable names, units and vector layout."""

    joint_names: tuple[str, ...]

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def n_kinematic(self) -> int:
        return 4 * self.n_joints

    @property
    def names(self) -> tuple[str, ...]:
        kin = tuple(f"{j}.{f}" for j in self.joint_names for f in FIELDS)
        return kin + BASE + TOOL

    @property
    def size(self) -> int:
        return self.n_kinematic + 9

    @property
    def is_length(self) -> np.ndarray:
        """(p,) True for lengths [m], False for angles [rad]."""
        kin = [f in LENGTH_FIELDS for _ in self.joint_names for f in FIELDS]
        return np.array(kin + [True, True, True, False, False, False] + [True] * 3)

    @property
    def is_kinematic(self) -> np.ndarray:
        mask = np.zeros(self.size, dtype=bool)
        mask[: self.n_kinematic] = True
        return mask

    def reporting_scale(self) -> np.ndarray:
        """(p,) size of one reporting unit per parameter: 1 mm or 1 deg, in SI."""
        return np.where(self.is_length, MM, DEG)

    def index(self, name: str) -> int:
        names = self.names
        try:
            return names.index(name)
        except ValueError:
            raise ParameterError(f"unknown parameter {name!r}." + suggest(name, names)
                                 + f" Valid names: {listing(names, 60)}", valid=names) from None

    def indices(self, names) -> np.ndarray:
        return np.array([self.index(n) for n in names], dtype=int)

    def split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(table (n, 4), base (6,), tool (3,)) views of a parameter vector."""
        k = self.n_kinematic
        return x[:k].reshape(self.n_joints, 4), x[k:k + 6], x[k + 6:k + 9]

    def join(self, table, base, tool) -> np.ndarray:
        return np.concatenate([np.asarray(table, float).ravel(), np.asarray(base, float),
                               np.asarray(tool, float)])
