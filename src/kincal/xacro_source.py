"""Expand a xacro file into URDF text, in Python, without ROS.

Robot descriptions are mostly published as xacro (``*.urdf.xacro``): macros, properties
and math over a URDF. kincal expands them with the ``xacro`` package from PyPI, the
reference expander that ROS itself runs, so a user does not need a ROS installation and
a separate step. The expanded text is then checked and loaded like any URDF; a corrected
URDF written from it is plain URDF (a xacro file cannot carry corrected numbers back
into its macros).

``$(find PKG)`` is resolved here, not by xacro (whose lookup needs ROS 2's
``ament_index_python``): a folder named PKG (or whose ``package.xml`` names it) above the
xacro file or beside one of those folders, then ``ROS_PACKAGE_PATH`` and
``AMENT_PREFIX_PATH`` / ``CMAKE_PREFIX_PATH`` (``share/PKG``), then the packages of the
installed example-robot-data. A package found nowhere is an error saying where kincal
looked and how to point it to the package.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import warnings
from pathlib import Path

from kincal.errors import KincalNote, KincalWarning, UrdfError

_ANSI = re.compile(r"\x1b\[[0-9;]*m")
_PACKAGE_NAME = re.compile(r"<name>\s*([^<\s]+)\s*</name>")


class _PackageNotFound(Exception):
    """Raised inside xacro's expansion; carries kincal's message out of it."""


def _declares(folder: Path, pkg: str) -> bool:
    """Whether ``folder`` is the ROS package ``pkg`` (by its package.xml, else its name)."""
    manifest = folder / "package.xml"
    if manifest.is_file():
        try:
            found = _PACKAGE_NAME.search(manifest.read_text(encoding="utf-8", errors="replace"))
        except OSError:
            found = None
        if found:
            return found.group(1) == pkg
    return folder.name == pkg and folder.is_dir()


def find_package(pkg: str, start: Path) -> Path:
    """The folder of ROS package ``pkg`` for a xacro file at ``start`` (see the module notes).

    Raises :class:`_PackageNotFound` with a message saying where kincal looked.
    """
    candidates: list[Path] = []
    for folder in Path(start).resolve().parents:
        candidates += [folder, folder / pkg]
    for entry in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep):
        if entry:
            candidates += [Path(entry), Path(entry) / pkg]
    for var in ("AMENT_PREFIX_PATH", "CMAKE_PREFIX_PATH"):
        for entry in os.environ.get(var, "").split(os.pathsep):
            if entry:
                candidates.append(Path(entry) / "share" / pkg)
    from kincal.descriptions import erd_robots_dir

    erd = erd_robots_dir()
    if erd is not None:
        candidates.append(erd / pkg)
    for folder in candidates:
        if folder.is_dir() and _declares(folder, pkg):
            return folder
    raise _PackageNotFound(
        f"$(find {pkg}): package {pkg!r} not found in the folders above {start}, beside "
        "them, on ROS_PACKAGE_PATH or AMENT_PREFIX_PATH; put the folder that holds it on "
        f"ROS_PACKAGE_PATH (export ROS_PACKAGE_PATH=/path/to/src)")


class _SeenArgs(dict):
    """xacro's argument values, noting every name xacro looks up: a ``<xacro:arg>`` the
    files declare or a ``$(arg NAME)`` they use. xacro reads the dict it is given as is."""

    def __init__(self, values):
        super().__init__(values)
        self.seen: set = set()

    def __contains__(self, name) -> bool:
        self.seen.add(name)
        return super().__contains__(name)

    def __getitem__(self, name):
        self.seen.add(name)
        return super().__getitem__(name)


def _unused(p: Path, given: dict, args: _SeenArgs) -> str | None:
    """Why an argument given for ``p`` would be ignored (xacro ignores a name no file
    declares or uses: a misspelt kinematics_params expands the default robot), or None."""
    unused = [name for name in given if name not in args.seen]
    if not unused:
        return None
    from kincal.errors import listing, suggest

    known = sorted(args.seen)
    return (f"{p}: xacro argument {', '.join(unused)} is neither declared nor used by this "
            f"file (xacro would ignore it); its arguments: {listing(known) or 'none'}."
            + suggest(unused[0], known))


@contextlib.contextmanager
def _package_lookup(start: Path):
    """xacro's $(find) answered by :func:`find_package` while the context is open.

    xacro offers no hook for this; its ``substitution_args._eval_find`` is the one
    function that resolves a package, so it is swapped for the expansion and restored.
    """
    from xacro import substitution_args

    original = substitution_args._eval_find
    substitution_args._eval_find = lambda pkg: str(find_package(pkg, start))
    try:
        yield
    finally:
        substitution_args._eval_find = original


def _cause(exc: BaseException) -> BaseException | None:
    """The first _PackageNotFound wrapped in ``exc`` (xacro wraps errors in its own)."""
    seen: set[int] = set()
    e: BaseException | None = exc
    while e is not None and id(e) not in seen:
        if isinstance(e, _PackageNotFound):
            return e
        seen.add(id(e))
        e = getattr(e, "exc", None) or e.__cause__ or e.__context__
    return None


def _process(p: Path, args) -> tuple[str, tuple[Path, ...]]:
    """(URDF text, the files xacro read: includes and ``load_yaml``\\ s) of ``p``'s expansion.
    Raises :class:`UrdfError`, one line, when it fails; xacro's warnings become
    :class:`KincalWarning`\\ s."""
    try:
        import xacro
    except ImportError:  # a dependency of kincal; only a broken install lacks it
        raise UrdfError(f"{p}: is a xacro file and the 'xacro' package is not installed; "
                        "pip install xacro, or expand it first: xacro FILE > robot.urdf") from None
    stderr = io.StringIO()
    seen = len(xacro.all_includes)  # xacro appends each file it reads (never resets)
    mappings = _SeenArgs(args or {})
    try:
        with _package_lookup(p), contextlib.redirect_stderr(stderr):
            doc = xacro.process_file(str(p.resolve()), mappings=mappings)
            text = doc.toprettyxml(indent="  ")
    except Exception as exc:  # xacro raises XacroException, expat, eval and OS errors
        cause = _cause(exc)
        stack = [str(f) for f in (getattr(xacro, "filestack", None) or []) if f]
        where = f" (in {stack[-1]})" if stack and stack[-1] != str(p.resolve()) else ""
        reason = str(cause) if cause is not None else (str(exc) or type(exc).__name__)
        reason = " ".join(_ANSI.sub("", reason).split())
        hint = ("; pass the file's arguments with --xacro-arg NAME:=VALUE"
                if "substitution argument" in reason and not args else "")
        raise UrdfError(f"{p}: xacro expansion failed{where}: {reason}{hint}") from None
    unused = _unused(p, dict(args or {}), mappings)
    if unused is not None:
        raise UrdfError(unused)
    read = tuple(Path(f) for f in xacro.all_includes[seen:])
    for line in dict.fromkeys(_ANSI.sub("", stderr.getvalue()).splitlines()):
        if line.startswith("warning:"):
            warnings.warn(f"{p}: xacro {line}", KincalWarning)
    return text, read


def expand_xacro(path, max_chars: int, args=None) -> str:
    """The URDF text that xacro makes of the file at ``path``, with ``args`` {name: value}
    for its ``xacro:arg``\\ s (the others at their defaults). Raises :class:`UrdfError`, one
    line, when the expansion fails or the result is over ``max_chars``; xacro's own
    warnings become :class:`KincalWarning`\\ s.
    """
    p = Path(path)
    text, _ = _process(p, args)
    if len(text) > max_chars:
        raise UrdfError(f"{p}: the expanded URDF has {len(text)} characters, more than "
                        f"{max_chars}; not a URDF kincal will read")
    warnings.warn(f"{p}: expanded with xacro (a corrected URDF is written as plain URDF)",
                  KincalNote)
    return text


def files_read(path, args=None) -> tuple[Path, ...]:
    """The files xacro reads when it expands ``path`` with ``args``, as xacro found them:
    a relative name (``kinematics_params:=K.yaml``) is joined to the folder of the xacro
    file that reads it, not to the working folder. Expands the file again (raises as
    :func:`expand_xacro`)."""
    return _process(Path(path), args)[1]
