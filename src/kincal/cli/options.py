"""The options the commands share: their argument groups, and the typed values they become.

Each command's ``run(args)`` turns the argparse Namespace into frozen values once, at its
top (:func:`typed`, :class:`Chain`, :class:`Inputs`, :class:`AccuracyRequest`); below that
line only these values travel, and nothing outside ``kincal.cli`` sees a Namespace.
No numpy at import: ``kincal --help`` builds every parser and loads nothing heavy.
"""

from __future__ import annotations

import argparse
import math
import dataclasses
from dataclasses import dataclass

from kincal.errors import OptionError

# the formats of kincal.measurements.orientation_columns (no numpy at import)
ORIENTATION_FORMATS = ("quat-xyzw", "quat-wxyz", "rpy-zyx", "rpy-xyz", "rotvec", "matrix")


# ------------------------------------------------------------------ groups
def group(p, title: str):
    """The argument group ``title`` of parser ``p`` (made on first use): --help by topic."""
    groups = p.__dict__.setdefault("_kincal_groups", {})
    if title not in groups:
        groups[title] = p.add_argument_group(title)
    return groups[title]


def _joint_column_pair(text: str) -> tuple[str, str]:
    """argparse type of --joint-columns: URDF_NAME=CSV_NAME."""
    urdf, eq, column = text.partition("=")
    if not eq or not urdf.strip() or not column.strip():
        raise argparse.ArgumentTypeError(f"expected URDF_NAME=CSV_NAME, got {text!r}")
    return urdf.strip(), column.strip()


def add_joint_columns(p, files="DATA"):
    # "extend": --joint-columns given twice adds to the mapping instead of replacing it
    group(p, "inputs").add_argument(
        "--joint-columns", nargs="+", action="extend", type=_joint_column_pair, default=[],
        metavar="URDF_NAME=CSV_NAME",
        help=f"read a chain joint from a column of another name in {files} "
             "(default: the column named as the URDF joint)")


def add_units(p, length="positions and prismatic joints in DATA",
              angle="revolute joints and orientation angles in DATA"):
    g = group(p, "inputs")
    g.add_argument("--length-unit", choices=("m", "mm"), default="m",
                   help=f"unit of {length} (default m)")
    g.add_argument("--angle-unit", choices=("rad", "deg"), default="rad",
                   help=f"unit of {angle} (default rad)")


def add_xacro_args(group_, flag: str = "--xacro-arg",
                   of: str = "a xacro robot description") -> None:
    """The xacro arguments of a robot description, NAME:=VALUE, repeatable: --xacro-arg for
    ROBOT; ``flag`` another description's (compensate's --nominal-xacro-arg), parsed by
    :func:`xacro_args` with the same flag."""
    group_.add_argument(flag, action="append", default=[], metavar="NAME:=VALUE",
                        help=f"an argument of {of} (repeatable), e.g. ur_type:=ur5e name:=ur5e")


def xacro_args(given, flag: str = "--xacro-arg") -> dict[str, str] | None:
    """{name: value} of ``flag`` NAME:=VALUE ..., or None; OptionError for a bad one."""
    out: dict[str, str] = {}
    for item in given or ():
        name, sep, value = item.partition(":=")
        if not sep or not name.strip() or any(c.isspace() for c in name.strip()):
            raise OptionError(f"{flag} expects NAME:=VALUE (as xacro and ros2 launch "
                              f"write it), got {item!r}")
        if name.strip() in out:
            raise OptionError(f"{flag} {name.strip()} given twice")
        out[name.strip()] = value
    return out or None


def add_common(p, data=True, chains=False):
    """ROBOT [DATA], the chain (--tip, --base, --tool-offset) and DATA's columns and units;
    chains: --tip and --base take one frame, or one per data file (several chains)."""
    inputs, chain = group(p, "inputs"), group(p, "chain")
    inputs.add_argument("robot", help="URDF path, 'ec66', or an example-robot-data name "
                        "(ur10, panda, ...)")
    if data:
        inputs.add_argument("data", help="CSV with the chain joint names and x,y,z")
    several = (" One frame for every data file, or one per data file: several chains of the "
               "robot calibrated together, a joint on several chains one set of parameters "
               "(error model placement or offsets)") if chains else ""
    nargs = {"nargs": "+", "metavar": "FRAME"} if chains else {}
    chain.add_argument("--tip", help="tip frame (link or joint name); default: the robot's usual "
                       "tip." + several, **nargs)
    chain.add_argument("--base", help="base frame (default: the URDF root link)." + several,
                       **nargs)
    add_xacro_args(inputs)
    if data:
        add_units(p)
        inputs.add_argument("--position-columns", nargs="+", default=("x", "y", "z"),
                            metavar="COL", help="names of the position columns: X Y Z, or "
                            "X1 Y1 Z1 X2 Y2 Z2 ... for several points measured at each pose")
        inputs.add_argument("--order-column", metavar="COL",
                            help="column giving the acquisition order (e.g. a time stamp), for "
                                 "the approach directions of backlash terms; default: the row order")
        add_joint_columns(p)
        inputs.add_argument("--joint-value", action="append", default=[], metavar="NAME=VALUE",
                            help="a chain joint the data files have no column for, held at "
                                 "VALUE during the measurements (in --angle-unit, or "
                                 "--length-unit if prismatic); repeatable")
    chain.add_argument("--tool-offset", nargs=3, type=float, metavar=("X", "Y", "Z"),
                       help="initial guess of the tool point in the tip frame, in the length unit")


def add_kinds(p, several: bool = True):
    """Measurement kinds (poses, distances, plane contacts) and further data files."""
    g = group(p, "inputs")
    if several:
        g.add_argument("more_data", nargs="*", metavar="MORE.csv",
                       help="further data files, each of its own kind, sharing the robot's "
                            "parameters (set 2, 3, ...: frame parameters set2.base.x, ...)")
    g.add_argument("--orientation-format", choices=ORIENTATION_FORMATS, metavar="FORMAT",
                   help="how a pose file writes its orientations: quat-xyzw (default; qx qy "
                        "qz qw, scalar last), quat-wxyz (scalar first), rpy-zyx (angles about "
                        "x, y, z read as R = Rz Ry Rx: URDF, FIGAROH's phix phiy phiz), "
                        "rpy-xyz (R = Rx Ry Rz), rotvec (axis times angle), matrix (r11 .. r33 "
                        "row by row); angles in --angle-unit")
    g.add_argument("--orientation-columns", nargs="+", metavar="COL",
                   help="orientation columns of a pose file, in the format's order (default: "
                        "qx qy qz qw; roll pitch yaw or phix phiy phiz; rx ry rz; r11 .. r33; "
                        "each also suffixed like the position columns, phix1 for x1)")
    g.add_argument("--positions-only", action="store_true",
                   help="read a file with orientation columns as positions only (without it, "
                        "unread orientation columns are refused)")
    g.add_argument("--orientation-sigma-deg", type=float,
                   help="orientation noise of pose files [deg] (default 0.01, against the "
                        "position sigma, 0.05 mm unless a sigma column says otherwise)")
    g.add_argument("--set-sigma-mm", nargs="+", type=float, metavar="S",
                   help="noise of each data file [mm] (position or distance), one per file in "
                        "order: weighs the files against each other (default: a 'sigma' "
                        "column, else 0.05 mm)")
    g.add_argument("--on-plane", action="store_true",
                   help="files with joint columns only are plane contacts (a 'plane' column "
                        "names each row's plane)")
    g.add_argument("--flush", action="store_true",
                   help="with --on-plane: each contact is a flat face pressed flush on the "
                        "plane (its height and two tilts; optional 'sigma' [length] and "
                        "'sigma_deg' columns; tilt noise --orientation-sigma-deg, default 0.05)")


def add_model(p, allow_all: bool = False, default: str | None = None, help: str | None = None,
              allow_auto: bool = False, auto: str | None = None):
    """--model NAME: the one definition of its choices (kincal.models) and default; with
    allow_auto "auto" (the default), ``auto`` what it means there (calibrate's: CV)."""
    from kincal.models import DEFAULT, MODELS, SUITS

    choices = (("auto",) if allow_auto else ()) + MODELS + (("all",) if allow_all else ())
    auto = "" if not allow_auto else "auto (default): " + (auto or (
        "the error models and, with approach directions, backlash terms compared by K-fold "
        "CV and the best used, the table shown")) + "; "
    group(p, "model and penalty").add_argument(
        "--model", choices=choices, default="auto" if allow_auto else default, metavar="NAME",
        help=help or (auto + (f"error model (default: {DEFAULT}; " if not allow_auto else "(")
                      + "placement on a tree path, a base off "
                      "the tip's branch): " + "; ".join(f"{k}: {v}" for k, v in SUITS.items())
                      + ("; all: compare every model" if allow_all else "")))


def add_accuracy_options(p):
    g = group(p, "predicted accuracy")
    g.add_argument("--accuracy-map", nargs=4, type=float, metavar=("CX", "CY", "CZ", "EDGE"),
                   help="predicted accuracy over a cube: centre and edge in the chain's base "
                        "frame, in the length unit; grid points reached by inverse kinematics")
    g.add_argument("--grid", type=int,
                   help="grid points per edge of the --accuracy-map cube (default 5)")
    g.add_argument("--accuracy-poses", metavar="POSES.csv",
                   help="predicted accuracy at these poses instead (chain joint columns)")


def add_overwrite(p, help="replace existing output files"):
    group(p, "outputs").add_argument("--overwrite", action="store_true", help=help)


def add_gate_overrides(p, what: str = "the outputs") -> None:
    """--accept-implausible and --accept-unconverged: write ``what`` despite the gate."""
    r = group(p, "the plausibility gate and the console")
    r.add_argument("--accept-implausible", action="store_true",
                   help=f"write {what} even if the plausibility gate finds the result "
                        "implausible (wrong units, rows, tip or data are the usual causes)")
    r.add_argument("--accept-unconverged", action="store_true",
                   help=f"write {what} even if the solver did not converge (best iterate)")


def add_console(p, json_summary: bool = False) -> None:
    """-q/--quiet and -v/--verbose (every command, added by the dispatcher), and --json
    where a command has a summary to give as JSON."""
    g = group(p, "console")
    g.add_argument("-q", "--quiet", action="store_true",
                   help="print nothing on stdout and no progress (warnings, errors and the "
                        "closing 'done in' line still go to stderr)")
    g.add_argument("-v", "--verbose", action="store_true",
                   help="say more: the version and command line first (stderr), the full "
                        "identifiability report (calibrate), the kind of an error")
    if json_summary:
        g.add_argument("--json", action="store_true",
                       help="the summary as JSON on stdout (nothing else there; what was "
                            "written is said on stderr)")


# ------------------------------------------------------------ typed values
def typed(cls, args: argparse.Namespace, **given):
    """The frozen dataclass ``cls`` from the Namespace: each field from the attribute of its
    name (lists become tuples; a missing attribute keeps the field's default), or from
    ``given``."""
    values = {}
    for f in dataclasses.fields(cls):
        if f.name in given:
            values[f.name] = given[f.name]
        elif hasattr(args, f.name):
            v = getattr(args, f.name)
            values[f.name] = tuple(v) if isinstance(v, list) else v
    return cls(**values)


def length_scale(unit: str) -> float:
    """Metres per ``unit`` ("m" or "mm"; the parser's choices, as
    :data:`kincal.measurements.data.LENGTH_UNITS` without numpy)."""
    return 1e-3 if unit == "mm" else 1.0


def angle_scale(unit: str) -> float:
    """Radians per ``unit`` ("rad" or "deg")."""
    return math.pi / 180.0 if unit == "deg" else 1.0


def tool_guess(offset, unit: str):
    """--tool-offset X Y Z in ``unit`` as a tuple [m], or None."""
    return None if offset is None else tuple(v * length_scale(unit) for v in offset)


@dataclass(frozen=True)
class Chain:
    """The robot and the chain of it a command works on."""

    robot: str  # URDF path, a bundled name or an example-robot-data name
    tip: str | None = None  # tip frame; None: the robot's usual tip (a tuple: see per_file)
    base: str | None = None  # base frame; None: the URDF root link (a tuple: see per_file)
    xacro_arg: tuple[str, ...] = ()  # NAME:=VALUE of a xacro description

    @classmethod
    def of(cls, args) -> "Chain":
        return typed(cls, args)

    def per_file(self, n_files: int) -> list["Chain"]:
        """The chain of each of ``n_files`` data files: --tip and --base give one frame (every
        file's) or one per file; any other count is refused."""
        given = {}
        for role in ("base", "tip"):
            v = getattr(self, role)
            v = (v,) if v is None or isinstance(v, str) else tuple(v)
            if len(v) not in (1, n_files):
                raise OptionError(f"--{role} takes one frame (for every data file) or one per "
                                  f"data file: {n_files} data files, {len(v)} --{role} frames "
                                  f"({' '.join(v)})")
            given[role] = v * (n_files if len(v) == 1 else 1)
        return [Chain(self.robot, t, b, self.xacro_arg)
                for b, t in zip(given["base"], given["tip"])]

    @staticmethod
    def load_all(chains: list["Chain"]) -> list:
        """The robot of every chain (one load per distinct chain)."""
        loaded: dict = {}
        for c in chains:
            if (c.base, c.tip) not in loaded:
                loaded[c.base, c.tip] = c.load()
        return [loaded[c.base, c.tip] for c in chains]

    def load(self):
        from kincal.robot import Robot

        return Robot.load(self.robot, tip=self.tip, base=self.base,
                          xacro_args=xacro_args(self.xacro_arg))

    def provenance(self, robot, data, command_line=(), **gate):
        """The provenance of a command's files (:meth:`kincal.export.provenance.Provenance.
        of_run`): ``robot`` as loaded from this chain, ``data`` the files read (None
        skipped), the command line as typed; ``gate``: verdict= and gate= where one ran."""
        from kincal.export.provenance import Provenance

        return Provenance.of_run(robot, data, command=command_line or None,
                                 xacro_args=xacro_args(self.xacro_arg), **gate)


@dataclass(frozen=True)
class Inputs:
    """The measurement files of a command and how to read them."""

    files: tuple[str, ...]  # DATA, then MORE.csv ...
    length_unit: str = "m"  # of positions and prismatic joints in the files
    angle_unit: str = "rad"  # of revolute joints in the files
    position_columns: tuple[str, ...] = ("x", "y", "z")
    order_column: str | None = None  # acquisition order, for backlash approach directions
    joint_columns: tuple[tuple[str, str], ...] = ()  # (URDF joint, CSV column) pairs
    orientation_columns: tuple[str, ...] | None = None  # of pose files, the format's order
    orientation_format: str | None = None  # None: quaternions qx qy qz qw if present
    positions_only: bool = False  # a file with orientation columns read as positions
    joint_value: tuple[str, ...] = ()  # NAME=VALUE of chain joints absent from the files
    orientation_sigma_deg: float | None = None  # [deg]
    set_sigma_mm: tuple[float, ...] | None = None  # [mm], one per file
    on_plane: bool = False  # joint-only files are plane contacts
    flush: bool = False  # ... pressed flush: height and two tilts per contact
    tool_offset: tuple[float, float, float] | None = None  # first guess, in length_unit

    @classmethod
    def of(cls, args) -> "Inputs":
        files = (args.data,) + tuple(getattr(args, "more_data", None) or ())
        return typed(cls, args, files=files)

    @property
    def data(self) -> str:
        return self.files[0]

    @property
    def tool_guess(self):
        """The tool point's first guess in the tip frame [m], or None."""
        return tool_guess(self.tool_offset, self.length_unit)

    def joint_map(self) -> dict[str, str] | None:
        """{URDF joint: CSV column} of --joint-columns, or None."""
        return joint_map(self.joint_columns)

    def _kind_options_used(self, stated: list[bool], has_angles: bool, whole: bool) -> None:
        """Refuse the options of pose files that no file would use. stated: per pose or
        flush file, whether a sigma_deg column states its orientation noise (the column wins
        over --orientation-sigma-deg); whole: the files are the run's data (a held-out file
        is judged with the noise of the training's)."""
        if self.positions_only and not has_angles:
            raise OptionError("--positions-only reads a pose file's positions alone; none of "
                              "the data files has orientation columns beside its positions")
        if self.orientation_sigma_deg is not None and not stated:
            raise OptionError("--orientation-sigma-deg is the orientation noise of pose files "
                              "(or the tilt noise of flush contacts); none of the data files "
                              "is one (" + ("read with --positions-only" if self.positions_only
                                            else "no qx qy qz qw columns")
                              + ", no --on-plane --flush)")
        if self.orientation_sigma_deg is not None and whole and all(stated):
            raise OptionError("--orientation-sigma-deg would weigh no row: every pose or flush "
                              "file states its orientation noise in a sigma_deg column, which "
                              "is used; leave out the option or the column")

    def held_joints(self, robots) -> dict[str, float]:
        """{joint: value [SI]} of --joint-value NAME=VALUE (the file's units)."""
        from kincal.measurements.fixed_joints import held_values

        return held_values(self.joint_value, robots, self.length_unit, self.angle_unit)

    def read_sets(self, robot, held=None, whole: bool = True) -> list:
        """Every data file, each read as its kind (on ``robot``'s chain, or with a list, on
        its own robot's), weighted by --set-sigma-mm if given. held: the joints a
        calibration held (:class:`~kincal.measurements.fixed_joints.HeldJoints`, from
        FRAMES.json): a file without a column for one gets its recorded value, unless
        --joint-value gives one (warned where it differs); a file with the column is read
        as it is (warned where it strays from the held value). whole: the files are the
        run's data (--on-plane must find a contact among them), not one held out."""
        import numpy as np

        from kincal.measurements.kind import SIGMA_RANGE_M
        from kincal.measurements.sets import check_contacts_read, kind_of, read_set_file

        if self.flush and not self.on_plane:
            raise OptionError("--flush describes plane contacts: give it with --on-plane")
        if self.set_sigma_mm:
            if len(self.set_sigma_mm) != len(self.files):
                raise OptionError(f"--set-sigma-mm takes one value per data file: "
                                  f"{len(self.files)} files, got {list(self.set_sigma_mm)}")
            lo, hi = SIGMA_RANGE_M
            for s in self.set_sigma_mm:
                if not (math.isfinite(s) and lo <= s * 1e-3 <= hi):
                    raise OptionError(f"--set-sigma-mm {s:g} is outside the accepted range "
                                      f"{lo * 1e3:g} mm to {hi * 1e3:g} mm (a file's "
                                      "measurement noise)")
        pos = self.position_columns if self.position_columns != ("x", "y", "z") else None
        robots = robot if isinstance(robot, (list, tuple)) else [robot] * len(self.files)

        from kincal.measurements import fixed_joints as fj

        given = self.held_joints(robots)
        held = held or fj.HeldJoints()
        kinds = {j: k for r in robots for j, k in zip(r.joint_names, r.geometry.kinds)}
        held.warn_given(given, kinds)
        angled = []  # per file: orientation columns beside its positions

        def read(path, r, fmt):
            from kincal.measurements.orientation_columns import found_columns
            from kincal.measurements.sets import header_of

            fixed = {j: v for j, v in given.items() if j in r.joint_names}
            columns = self.joint_map() or {}
            header = header_of(path, [columns.get(j, j) for j in r.joint_names])
            fj.check_absent(path, header, fixed, self.joint_map())
            fixed.update({j: v for j, v in held.values if j in r.joint_names
                          and j not in fixed and columns.get(j, j) not in header})
            angled.append(all(c in header for c in pos or "xyz") and bool(found_columns(
                header, pos, [columns.get(j, j) for j in r.joint_names])))
            follow = fj.mimicked(path, header, r, fixed, self.joint_map())
            d = read_set_file(path, [j for j in r.joint_names if j not in {*fixed, *follow}],
                              _prismatic(r), self.length_unit, self.angle_unit, pos,
                              self.orientation_columns, self.on_plane,
                              self.orientation_sigma_deg, self.joint_map(), self.order_column,
                              flush=self.flush, orientation_format=fmt,
                              positions_only=self.positions_only)
            # a mimic column off its rule is warned by the problem (the API's path too)
            held.warn_off(path, d.joint_names, kinds, d.joint_values, "its values are read as "
                          "they are; the calibration holds at the recorded value only", d.rows)
            return fj.with_fixed_joints(d, r.joint_names, fixed, follow) if fixed or follow else d

        from kincal.identification.orientation_convention import checked
        from kincal.identification.problem import CalibrationProblem

        # a convention the columns do not fix is held against the nominal model (warned now;
        # the gate refuses a calibration of a reading in doubt)
        sets = [checked(CalibrationProblem, r, read(path, r, self.orientation_format))
                for path, r in zip(self.files, robots)]
        self._kind_options_used([d.sigma_deg is not None for d in sets
                                 if kind_of(d) in ("pose", "flush")], any(angled), whole)
        check_contacts_read(sets, self.files, self.on_plane and whole, self.flush)
        if self.set_sigma_mm:
            sets = [dataclasses.replace(d, sigma=np.full(len(d), s * 1e-3))
                    for d, s in zip(sets, self.set_sigma_mm)]
        return sets


def _prismatic(robot) -> list[str]:
    return [n for n, k in zip(robot.joint_names, robot.geometry.kinds) if k == "prismatic"]


def joint_map(pairs) -> dict[str, str] | None:
    if not pairs:
        return None
    mapping: dict[str, str] = {}
    for urdf, column in pairs:
        if urdf in mapping:
            raise OptionError(f"--joint-columns names joint {urdf} twice")
        mapping[urdf] = column
    return mapping


@dataclass(frozen=True)
class AccuracyRequest:
    """Where to predict the accuracy: a cube (--accuracy-map) or poses (--accuracy-poses)."""

    accuracy_map: tuple[float, float, float, float] | None = None  # CX CY CZ EDGE, length unit
    grid: int = 5  # grid points per edge of the cube
    accuracy_poses: str | None = None  # POSES.csv
    length_unit: str = "m"
    angle_unit: str = "rad"

    @classmethod
    def of(cls, args) -> "AccuracyRequest":
        return typed(cls, args)

    @property
    def asked(self) -> bool:
        return self.accuracy_map is not None or self.accuracy_poses is not None

    def targets(self, robot) -> dict:
        """Keyword arguments of the accuracy-map functions; raises on bad values."""
        import numpy as np

        if self.accuracy_map is not None and self.accuracy_poses is not None:
            raise OptionError("give at most one of --accuracy-map and --accuracy-poses")
        k = length_scale(self.length_unit)
        if self.accuracy_map is not None:
            from kincal.planning.accuracy_map import cube_grid

            c = self.accuracy_map
            cube_grid(np.array(c[:3]) * k, c[3] * k, self.grid)  # raises on bad values
            return {"cube": (np.array(c[:3]) * k, c[3] * k), "grid": self.grid}
        if self.accuracy_poses is not None:
            from kincal.planning.candidates import read_candidates

            q, _ = read_candidates(self.accuracy_poses, robot, self.length_unit, self.angle_unit,
                                   kind="accuracy poses")
            return {"joint_values": q, "targets": f"the {len(q)} poses of {self.accuracy_poses}"}
        return {}
