"""Writing files as one transaction that never loses what the user gave.

Every file kincal writes (corrected URDF, frames and report JSON, CSV, plots) goes
through :func:`write_all` (or its one-file forms :func:`write_text_atomic` and
:func:`write_bytes_atomic`), in three steps:

1. check every target (:func:`check_outputs`, which the CLI also calls before the work,
   so that a run that would be refused at the end is refused at the start);
2. stage: each file is written to a temporary file beside its target and fsync'ed;
3. commit: each temporary file takes its target's name. A new file is put in place by
   ``os.link(temporary, target)``, which fails if the target exists: the existence
   check and the rename are one step, so of two runs racing for one output exactly one
   wins and the other gets a clean error. A file replaced with ``overwrite`` keeps a
   hard-linked backup until the whole transaction is done.

If anything fails (a full disk, a lost race, Ctrl-C), every file committed so far is
removed or restored from its backup, the temporary files are removed, and a folder the
transaction created is removed again: all of the outputs, or none, and nothing of the
user's changed. Only regular files are written: a FIFO, a device or a socket as a
target is refused, with or without ``overwrite``.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from pathlib import Path

from kincal.errors import ExportError

OVERWRITE = "pass --overwrite (Python: overwrite=True)"  # how a user replaces a file
_NO_HARD_LINKS = (errno.EPERM, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EXDEV, errno.EMLINK,
                  errno.ENOSYS)


def write_text_atomic(path, text: str, *, overwrite: bool = False, protect=()) -> Path:
    """Write ``text`` as UTF-8 (line endings as given) to ``path``; return the resolved path."""
    return write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite, protect=protect)


def write_bytes_atomic(path, data: bytes, *, overwrite: bool = False, protect=()) -> Path:
    """Write ``data`` to ``path`` atomically; return the resolved path.

    A reader sees the old file or the new one, never half of one, and a failure leaves
    no temporary file. Raises :class:`ExportError` unless ``overwrite`` for an existing
    target; always for one of the ``protect`` paths (the user's inputs, recognised through
    symlinks, relative paths and hard links), a directory, a non-regular
    file or a missing parent directory (never created silently). A symlink is written
    through: the file it names changes.
    """
    return write_all([(path, data)], overwrite=overwrite, protect=protect)[0]


def _kind(mode: int) -> str:
    for test, name in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return name
    return "not a regular file"


def _path_error(path, exc: BaseException) -> ExportError:
    """One line for an OS error met while looking at output ``path``."""
    try:
        os.getcwd()
    except OSError:
        return ExportError(f"{path}: the working folder no longer exists (deleted while kincal "
                           "was running?); no output was written or changed")
    if isinstance(exc, RuntimeError) or getattr(exc, "errno", None) == errno.ELOOP:
        return ExportError(f"{path}: is a symlink loop; choose another output path")
    if getattr(exc, "errno", None) == errno.ENAMETOOLONG:
        return ExportError(f"{str(path)[:60]}...: file name too long (a name is at most 255 "
                           "bytes, a path at most 4096); choose a shorter output path")
    return ExportError(f"{path}: {getattr(exc, 'strerror', None) or exc}")


def _writable(folder: Path, path) -> None:
    """Refuse now a folder in which no file can be made (permissions, read-only mount)."""
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ExportError(f"{path}: cannot write in {folder} (permission denied or a "
                          "read-only file system); choose another output path")


def _check_dir(path, new_dirs: set) -> Path:
    """The resolved folder ``path``; it must be a folder or creatable in one (one level).
    An empty path is refused: ``Path("")`` is the current folder, where a folder option
    left empty (``--out-dir "$UNSET"``) would have put its files."""
    if not isinstance(path, (str, os.PathLike)) or str(path) == "":
        raise ExportError(f"an output folder must be a non-empty str or Path, got {path!r}")
    try:
        return _check_dir_os(path, new_dirs)
    except (OSError, RuntimeError) as exc:
        raise _path_error(path, exc) from None


def _check_dir_os(path, new_dirs: set) -> Path:
    d = Path(path).expanduser().resolve()
    if d.exists():
        if not d.is_dir():
            raise ExportError(f"{path}: exists and is not a directory")
        _writable(d, path)
        return d
    if d.parent in new_dirs:
        return d
    if d.parent.is_dir():
        _writable(d.parent, path)
        return d
    p = d.parent
    while not p.exists():
        p = p.parent
    if not p.is_dir():
        raise ExportError(f"{path}: {p} is a file, not a directory")
    raise ExportError(f"{path}: directory {d.parent} does not exist")


def _check_target(path, overwrite: bool, protect, new_dirs=frozenset(), in_place=()) -> Path:
    """The checks of :func:`write_all` for one file, without writing anything."""
    if not isinstance(path, (str, os.PathLike)) or str(path) == "":
        raise ExportError(f"an output path must be a non-empty str or Path, got {path!r}")
    try:
        return _check_target_os(path, overwrite, protect, new_dirs, in_place)
    except (OSError, RuntimeError) as exc:
        raise _path_error(path, exc) from None


def _same_file(a: Path, b: Path) -> bool:
    """Whether paths ``a`` and ``b`` name one file (symlinks, relative paths, hard links)."""
    a, b = Path(a).expanduser(), Path(b).expanduser()
    return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))


def _check_target_os(path, overwrite: bool, protect, new_dirs, in_place=()) -> Path:
    given = Path(path).expanduser()
    target = given.resolve()
    for protected in protect:
        protected = Path(protected).expanduser()
        if not _same_file(target, protected):
            continue
        if not any(_same_file(target, out) and _same_file(protected, source)
                   for out, source in in_place):
            raise ExportError(f"{path}: refusing to overwrite the input file {protected}, "
                              "with or without --overwrite (an output never replaces what "
                              "the command read, but for the corrected URDF its robot "
                              "description); choose another output path")
        if not overwrite:
            raise ExportError(f"{path}: refusing to overwrite the input file {protected}; "
                              "choose another output path or " + OVERWRITE)
    if target.exists():
        mode = target.stat().st_mode
        if stat.S_ISDIR(mode):
            raise ExportError(f"{path}: is a directory")
        if not stat.S_ISREG(mode):
            raise ExportError(f"{path}: is {_kind(mode)}; kincal writes regular files only")
        if not overwrite:
            raise ExportError(f"{path}: already exists; choose another output path or "
                              + OVERWRITE)
    elif given.is_symlink() and not overwrite:
        raise ExportError(f"{path}: already exists (a dangling symlink); choose another output "
                          "path or " + OVERWRITE)
    if target.parent not in new_dirs and not target.parent.is_dir():
        p = target.parent
        while not p.exists() and p != p.parent:
            p = p.parent
        if p.exists() and not p.is_dir():
            raise ExportError(f"{path}: {p} is a file, not a directory")
        raise ExportError(f"{path}: directory {target.parent} does not exist")
    if target.parent not in new_dirs:
        _writable(target.parent, path)
    return target


def missing_folders(path) -> list[Path]:
    """The folders of ``path`` that do not exist yet, outermost first, ``path`` included
    if missing: the ``dirs`` of :func:`write_all` for a folder that may be nested in new
    ones (made with the files, removed again if the writing fails)."""
    d = Path(path).expanduser().resolve()
    out: list[Path] = []
    while not d.exists() and d != d.parent:
        out.append(d)
        d = d.parent
    return out[::-1]


def check_outputs(paths, *, overwrite: bool = False, protect=(), dirs=(),
                  in_place=()) -> list[Path]:
    """Check, before any work, that :func:`write_all` could write ``paths``; return them resolved.

    dirs: folders the transaction may create (one level below an existing folder),
    e.g. a plots folder; files may name them as parents. protect: the inputs, never
    replaced, but for the (output, input) pairs of ``in_place`` with ``overwrite`` (the
    corrected URDF written over its robot description). Raises :class:`ExportError`
    naming the first target that would be refused, and the same for two paths naming
    one file.
    """
    new_dirs: set[Path] = set()
    for d in dirs:
        r = _check_dir(d, new_dirs)
        if not r.exists():
            new_dirs.add(r)
    targets = [_check_target(p, overwrite, protect, new_dirs, in_place) for p in paths]
    if len(set(targets)) != len(targets):
        raise ExportError("two outputs name the same file: " + ", ".join(str(p) for p in paths))
    return targets


def _default_mode(target: Path) -> int:
    """Mode of the file being replaced, else what open() would give under the umask."""
    if target.exists():
        return target.stat().st_mode & 0o7777
    umask = os.umask(0)  # reading the umask means setting it; restored at once
    os.umask(umask)
    return 0o666 & ~umask


def _stage(target: Path, data, path) -> str:
    """A temporary file beside ``target`` holding ``data`` (bytes, or an iterable of bytes
    pieces), fsync'ed; returns its path."""
    try:
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    except OSError as exc:
        raise ExportError(f"{path}: cannot write in {target.parent} ({exc.strerror or exc})") from exc
    try:
        with os.fdopen(fd, "wb") as f:
            for piece in (data,) if isinstance(data, bytes) else data:
                f.write(piece)
            f.flush()
            os.fsync(f.fileno())
        # mkstemp makes the file 0600; give it the mode a plain open() would
        os.chmod(tmp, _default_mode(target))
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return tmp


def _encoded(pieces):
    """UTF-8 bytes of an iterable of str pieces, one piece at a time."""
    for piece in pieces:
        yield piece.encode("utf-8")


def _place_new(tmp: str, target: Path, path) -> None:
    """Give ``tmp`` the name ``target``, failing if the name is taken (no lost race)."""
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise ExportError(f"{path}: already exists (created while kincal was running); "
                          "choose another output path or " + OVERWRITE) from None
    except OSError as exc:
        if exc.errno not in _NO_HARD_LINKS:
            raise
        # no hard links here (some network and FUSE file systems): claim the name with
        # an exclusive create, then move the content over the placeholder
        try:
            os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except FileExistsError:
            raise ExportError(f"{path}: already exists (created while kincal was running); "
                              "choose another output path or " + OVERWRITE) from None
        try:
            os.replace(tmp, target)
        except BaseException:
            target.unlink(missing_ok=True)  # our placeholder
            raise
        return
    os.unlink(tmp)


def _backup(target: Path) -> str:
    """A hard link to the file about to be replaced (a copy if links are not possible)."""
    name = tempfile.mktemp(dir=target.parent, prefix=f".{target.name}.", suffix=".bak")
    try:
        os.link(target, name)
    except OSError as exc:
        if exc.errno not in _NO_HARD_LINKS:
            raise
        import shutil

        shutil.copy2(target, name)
    return name


def write_all(files, *, overwrite: bool = False, protect=(), dirs=(), shared_dirs=(),
              in_place=(), before_commit=None) -> list[Path]:
    """Write several files as one transaction: all of them, or none; return the resolved paths.

    files: (path, content) pairs, the content bytes, str, or an iterable of str pieces
    (staged piece by piece, never joined: a large file written in blocks). dirs: folders
    that may be created for them (see :func:`check_outputs`; protect and in_place as
    there). shared_dirs: folders, outermost first and before ``dirs``, made if missing like
    those but never removed again, even when the writing fails: a folder that other
    writers running at the same time make and fill too (a fleet's folder, which one unit's
    failure must not pull from under another unit about to write into it; its owner, the
    fleet command, removes it if the run leaves it empty). Every target is checked before
    the first byte is written, all contents are staged next to their targets, then
    committed; a failure at any
    point (KeyboardInterrupt included) restores every target and removes what was made.
    before_commit: called with the resolved targets once everything is staged, before the
    first target takes its name; if it raises, nothing is written (the CLI prints and
    flushes its console output there, so a console that fails leaves no file behind).
    """
    files = [(p, d.encode("utf-8") if isinstance(d, str) else d) for p, d in files]
    files = [(p, d if isinstance(d, bytes) else _encoded(d)) for p, d in files]
    targets = check_outputs([p for p, _ in files], overwrite=overwrite, protect=protect,
                            dirs=[*shared_dirs, *dirs], in_place=in_place)
    made_dirs: list[Path] = []
    staged: list[str] = []
    done: list[tuple[Path, str | None]] = []  # (target, backup or None for a new file)
    current = "the outputs"
    try:
        for d in shared_dirs:  # made if missing, never ours to remove
            Path(d).expanduser().resolve().mkdir(exist_ok=True)
        for d in dirs:
            d = Path(d).expanduser().resolve()
            if not d.exists():
                try:
                    d.mkdir()
                except FileExistsError:  # made meanwhile (another unit of a fleet writing
                    if not d.is_dir():   # into the same folder): not ours to remove
                        raise
                    continue
                made_dirs.append(d)
        for (path, data), target in zip(files, targets):
            current = path
            staged.append(_stage(target, data, path))
        if before_commit is not None:
            before_commit(targets)
        for (path, _), target, tmp in zip(files, targets, staged):
            current = path
            if not (overwrite and target.exists()):
                try:
                    _place_new(tmp, target, path)
                    done.append((target, None))
                    continue
                except ExportError:
                    if not overwrite:
                        raise
                    # appeared meanwhile, and the user allows replacing it: below
            if not stat.S_ISREG(target.stat().st_mode):  # swapped in meanwhile
                raise ExportError(f"{path}: is {_kind(target.stat().st_mode)}; kincal "
                                  "writes regular files only")
            done.append((target, _backup(target)))
            os.replace(tmp, target)
    except BaseException as exc:
        _roll_back(done, staged, made_dirs)
        if isinstance(exc, OSError):
            raise ExportError(f"{current}: could not write ({exc.strerror or exc}); no output "
                              "was written or changed") from exc
        raise
    for _, backup in done:
        if backup is not None:
            Path(backup).unlink(missing_ok=True)
    for parent in {t.parent for t in targets}:
        _fsync_dir(parent)
    return targets


def _roll_back(done, staged, made_dirs) -> None:
    """Undo a partial commit: restore replaced files, remove new ones, temps and new folders."""
    for target, backup in reversed(done):
        try:
            if backup is None:
                target.unlink(missing_ok=True)
            elif not (target.exists() and os.path.samefile(target, backup)):
                os.replace(backup, target)  # else the replace never happened
        except OSError:
            pass  # best effort: keep undoing the others
    for tmp in staged:
        Path(tmp).unlink(missing_ok=True)
    for target, backup in done:
        if backup is not None:
            Path(backup).unlink(missing_ok=True)
    for d in reversed(made_dirs):
        try:
            d.rmdir()
        except OSError:
            pass


def _fsync_dir(directory: Path) -> None:
    """Make the renames durable too; best effort, not every platform opens directories."""
    try:
        dir_fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError:
        pass
