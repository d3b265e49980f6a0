"""A simulated fleet of one robot model, for the fleet scripts and tests.

Units = nominal + one systematic deviation shared by the fleet (as built, not as designed)
+ a unit-to-unit scatter (``scatter`` times the systematic deviation's scale, per
parameter), simulated on the MD-H table (:mod:`kincal.planning.simulation`). Each unit is
measured in a wide cube by a laser tracker or in a small cube by an R-test, in a measurement
frame of its own, with its own tool point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from kincal.measurements.data import Measurements
from kincal.measurements.point_space import DEG, MM, ParameterSpace
from kincal.models import mdh as mdh_layer
from kincal.planning.simulation import Truth, cube_poses, measure
from kincal.models.base import ErrorModel
from kincal.robot import Robot



@dataclass(frozen=True)
class FleetModel:
    """A robot model's fleet. robot: the nominal robot; model: its MD-H error model (the
    simulator); systematic: (k,) the deviation every unit shares [m, rad]; scatter_sd: (k,)
    the unit-to-unit standard deviation about it [m, rad]."""

    robot: Robot
    model: ErrorModel
    systematic: np.ndarray
    scatter_sd: np.ndarray
    compliance: float = 0.0  # [rad] joint 2 and 3 sag no kinematic model carries

    @classmethod
    def of(cls, robot: Robot, seed: int, length_sd: float = 0.3 * MM,
           angle_sd: float = 0.03 * DEG, scatter: float = 0.25,
           compliance: float = 0.0) -> "FleetModel":
        model = mdh_layer.extract(robot.geometry)
        rng = np.random.default_rng([seed, 7])
        space = ParameterSpace.of_model(model)
        length = np.asarray(space.is_length[:space.n_kinematic], bool)
        sd = np.where(length, length_sd, angle_sd)
        return cls(robot, model, rng.normal(size=sd.size) * sd, scatter * sd, compliance)

    def unit(self, rng: np.random.Generator) -> np.ndarray:
        """(k,) one unit's true MD-H table (flat) [m, rad]."""
        return (self.model.nominal + self.systematic
                + rng.normal(size=self.systematic.size) * self.scatter_sd)

    def measure(self, table: np.ndarray, rng: np.random.Generator, n: int, center,
                edge: float, tool, noise: float, max_tilt_deg: float,
                source: str = "<simulated>") -> Measurements:
        """n poses in a cube of ``edge`` [m] about ``center`` (base frame), the tool point
        ``tool`` in the flange [m], seen from a random measurement frame, with noise [m]."""
        tool = np.asarray(tool, float)
        q = cube_poses(self.robot, n, center, edge, tool, rng,
                       max_tilt=math.radians(max_tilt_deg))
        base = np.concatenate([rng.normal(size=3) * 0.5, rng.normal(size=3) * 0.3])
        return measure(self.model, Truth(table, base, tool, self.compliance), q, noise, rng, source=source)

    def tracker(self, table, rng, tool=(0, 0, 0.045), n: int = 60, source="<tracker>"):
        """A wide calibration: n poses in a 400 mm cube, 10 um noise."""
        return self.measure(table, rng, n, (0.4, 0.0, 0.15), 0.4, tool, 1e-5, 30, source)

    def rtest(self, table, rng, tool=(0, 0, 0.11), n: int = 60, source="<R-test>"):
        """A small-volume calibration: n poses in a 20 mm cube, 50 um noise."""
        return self.measure(table, rng, n, (0.4, 0.0, 0.25), 0.02, tool, 5e-5, 15, source)

    def tracker_files(self, folder, units: int, rng, n: int = 60, width: int = 2,
                      overwrite: bool = False) -> list[str]:
        """Write ``units`` units of the fleet, each a :meth:`tracker` calibration of n
        poses, as CSV files u01.csv, u02.csv, ... (numbers ``width`` digits wide) in
        ``folder``, all or none through the one writer (provenance ``#`` lines: the
        nominal robot, the Python API); returns their paths (a fleet for the tests and
        benchmarks)."""
        from pathlib import Path

        from kincal.export.outputs import File, write_files
        from kincal.export.provenance import Provenance

        files = [File(Path(folder) / f"u{u + 1:0{width}d}.csv", "csv",
                      self.tracker(self.unit(rng), rng, n=n).to_csv_text())
                 for u in range(units)]
        write_files(files, Provenance.of_run(self.robot), overwrite=overwrite)
        return [str(f.path) for f in files]
