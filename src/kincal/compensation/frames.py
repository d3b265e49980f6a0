"""The frames of a calibrated cell: measurement frame, tool point(s), backlash terms.

What ``kincal calibrate --frames-out`` writes (FRAMES.json) and what
:meth:`kincal.identification.result.CalibrationResult.frames_dict` returns:
``P_measured = R_base (p_tip + R_tip t_tool) + t_base``, ``R_base = rotx(rx) roty(ry)
rotz(rz)``, metres and radians. The file records the chain it belongs to (base and tip
frame, and the chain joints since this version), so frames of another robot or tip are
refused instead of silently giving wrong joint values.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kincal.errors import DataError, InputFileError
from kincal.rotations import base_rotation, transform


@dataclass(frozen=True)
class CellFrames:
    """Measurement frame and tool points of a calibration (SI units).

    base: (6,) x, y, z [m], rx, ry, rz [rad] of the robot's base frame B in the
    measurement frame M. tools: (K, 3) measured points in the tip frame [m].
    backlash: {joint: half the play [rad or m]}. base_frame, tip_frame, joints: the
    chain the frames belong to ("" / () when the file does not say). source: for messages.
    """

    base: np.ndarray
    tools: np.ndarray
    backlash: dict = field(default_factory=dict)
    base_frame: str = ""
    tip_frame: str = ""
    joints: tuple[str, ...] = ()
    source: str = "<frames>"

    @classmethod
    def from_dict(cls, data: dict, source: str = "<frames>") -> "CellFrames":
        """From the content of a FRAMES.json (or ``CalibrationResult.frames_dict()``)."""
        try:
            base = [float(data["base"][k]) for k in ("x", "y", "z", "rx", "ry", "rz")]
            tools = [[float(t[k]) for k in ("x", "y", "z")]
                     for t in data.get("tool_points", [data["tool"]])]
            backlash = {str(j): float(v) for j, v in data.get("backlash", {}).items()}
            joints = tuple(str(j) for j in data.get("joints", ()))
            base_frame, tip_frame = str(data.get("base_frame", "")), str(data.get("tip_frame", ""))
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise DataError(f"{source}: not a kincal frames file ({exc.__class__.__name__}: "
                            f"{exc}); expected {{\"base\": {{\"x\",\"y\",\"z\",\"rx\",\"ry\",\"rz\"}}, "
                            "\"tool\": {\"x\",\"y\",\"z\"}} in metres and radians") from None
        values = base + [v for t in tools for v in t] + list(backlash.values())
        if not tools or not all(math.isfinite(v) for v in values):
            raise DataError(f"{source}: frames contain a non-finite number or no tool point")
        return cls(np.array(base), np.array(tools), backlash, base_frame, tip_frame, joints,
                   source)

    @classmethod
    def read(cls, path) -> "CellFrames":
        """From a FRAMES.json file."""
        from kincal.input_files import MAX_JSON_BYTES, check_regular_file

        path = Path(path)
        if not path.exists():
            raise InputFileError(f"frames file not found: {path}")
        check_regular_file(path, "frames", MAX_JSON_BYTES)  # no FIFO, device or huge file
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise DataError(f"{path}: not a kincal frames file ({exc})") from None
        if not isinstance(data, dict):
            raise DataError(f"{path}: not a kincal frames file (a JSON object was expected)")
        return cls.from_dict(data, str(path))

    def check_chain(self, robot) -> None:
        """Refuse frames identified on another chain than ``robot``'s (base, tip, joints)."""
        theirs = {"base frame": self.base_frame, "tip frame": self.tip_frame}
        mine = {"base frame": robot.base, "tip frame": robot.tip}
        for what in theirs:
            if theirs[what] and theirs[what] != mine[what]:
                raise DataError(f"{self.source} belongs to the {what} {theirs[what]!r}, this "
                                f"robot's chain has {mine[what]!r} ({robot.base} -> {robot.tip}): "
                                "frames from another robot or tip would give wrong joint "
                                "values; use the frames written with this calibration, or "
                                f"--tip/--base {theirs[what]} if that is the chain you meant")
        if self.joints and tuple(self.joints) != tuple(robot.joint_names):
            raise DataError(f"{self.source} was identified on the chain joints "
                            f"{', '.join(self.joints)}, this robot's chain has "
                            f"{', '.join(robot.joint_names)}: frames from another robot")
        unknown = [j for j in self.backlash if j not in robot.joint_names]
        if unknown:
            raise DataError(f"{self.source}: backlash of {', '.join(unknown)}, which are not "
                            f"chain joints of {robot.name} ({', '.join(robot.joint_names)})")

    @property
    def T_measurement_base(self) -> np.ndarray:
        """(4, 4) pose of the base frame B in the measurement frame M [m]."""
        return transform(base_rotation(*self.base[3:]), self.base[:3])
