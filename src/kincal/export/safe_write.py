"""Atomic file writing that never loses what the user gave.

Every file kincal writes (corrected URDF, frames and report JSON, CSV, plots) goes
through :func:`write_text_atomic` or :func:`write_bytes_atomic`: a temporary file in the
target directory, fsync, then ``os.replace``. A reader sees the old file or the new one,
never half of one; a failure leaves nothing behind; the user's inputs are refused as
targets unless overwriting is asked for.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from kincal.errors import ExportError


def write_text_atomic(path, text: str, *, overwrite: bool = False, protect=()) -> Path:
    """Write ``text`` as UTF-8 (line endings as given) to ``path``; return the resolved path."""
    return write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite, protect=protect)


def write_bytes_atomic(path, data: bytes, *, overwrite: bool = False, protect=()) -> Path:
    """Write ``data`` to ``path`` atomically; return the resolved path.

    Temporary file in the same directory, fsync, ``os.replace``: a reader sees the old
    file or the new one, never half of one, and a failure leaves no temporary file.
    Raises :class:`ExportError` unless ``overwrite`` for an existing target or one of
    the ``protect`` paths (the user's inputs, recognised through symlinks, relative
    paths and hard links); always for a directory or a missing parent directory
    (never created silently). A symlink is written through: the file it names changes.
    """
    target = Path(path).expanduser().resolve()
    if not overwrite:
        for protected in protect:
            protected = Path(protected).expanduser()
            if target == protected.resolve() or (
                    target.exists() and protected.exists() and os.path.samefile(target, protected)):
                raise ExportError(f"{path}: refusing to overwrite the input file {protected}; "
                                  "choose another output path or pass overwrite=True")
        if target.exists() or Path(path).expanduser().is_symlink():
            raise ExportError(f"{path}: already exists; choose another output path or pass overwrite=True")
    if target.is_dir():
        raise ExportError(f"{path}: is a directory")
    if not target.parent.is_dir():
        raise ExportError(f"{path}: directory {target.parent} does not exist")

    try:
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    except OSError as exc:
        raise ExportError(f"{path}: cannot write in {target.parent} ({exc.strerror or exc})") from exc
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        # mkstemp makes the file 0600; give it the mode a plain open() would
        os.chmod(tmp, _default_mode(target))
        os.replace(tmp, target)
    except BaseException as exc:  # KeyboardInterrupt too: never leave the temporary file
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise ExportError(f"{path}: could not write ({exc.strerror or exc})") from exc
        raise
    try:  # make the rename durable too; best effort, not every platform opens directories
        dir_fd = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError:
        pass
    return target


def _default_mode(target: Path) -> int:
    """Mode of the file being replaced, else what open() would give under the umask."""
    if target.exists():
        return target.stat().st_mode & 0o7777
    umask = os.umask(0)  # reading the umask means setting it; restored at once
    os.umask(umask)
    return 0o666 & ~umask


def _check_target(path, overwrite: bool, protect) -> Path:
    """The checks of :func:`write_bytes_atomic`, without writing anything."""
    target = Path(path).expanduser().resolve()
    for protected in protect:
        protected = Path(protected).expanduser()
        same = target == protected.resolve() or (
            target.exists() and protected.exists() and os.path.samefile(target, protected))
        if same and not overwrite:
            raise ExportError(f"{path}: refusing to overwrite the input file {protected}; "
                              "choose another output path or pass --overwrite")
    if target.is_dir():
        raise ExportError(f"{path}: is a directory")
    if target.exists() and not overwrite:
        raise ExportError(f"{path}: already exists; choose another output path or pass --overwrite")
    if not target.parent.is_dir():
        raise ExportError(f"{path}: directory {target.parent} does not exist")
    return target


def write_all(files, *, overwrite: bool = False, protect=()) -> list[Path]:
    """Write several files as one transaction: all of them, or none.

    files: (path, bytes or str) pairs. Every target is checked before the first byte is
    written; if a later write fails, the files this call created are removed again and
    the ones it replaced... cannot be brought back, so replacing needs ``overwrite``.
    """
    files = [(p, d.encode("utf-8") if isinstance(d, str) else d) for p, d in files]
    targets = [_check_target(p, overwrite, protect) for p, _ in files]
    if len(set(targets)) != len(targets):
        raise ExportError("two outputs name the same file: "
                          + ", ".join(str(p) for p, _ in files))
    created, written = [], []
    try:
        for (path, data), target in zip(files, targets):
            existed = target.exists()
            written.append(write_bytes_atomic(path, data, overwrite=overwrite, protect=protect))
            if not existed:
                created.append(target)
    except BaseException:
        for target in created:
            target.unlink(missing_ok=True)
        raise
    return written
