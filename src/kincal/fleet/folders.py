"""The units' folders of a fleet: staged by each unit, put in place together once the fleet
has succeeded, or discarded.

Each unit writes its files into ``DIR/.partial-<unit>`` (:mod:`kincal.fleet.unit`) while the
fleet runs. Whether they become results is the fleet's outcome, known only at its end: a
fleet that fails (fewer than two units calibrated, no prior) must leave no unit's files
that a pipeline could take for its result, and must not have replaced the earlier run's.
So the command either commits every staged unit (:func:`commit_units`: each staging folder
takes its unit's name, an earlier ``DIR/<unit>`` moved aside first; all or none) and then
writes the summary and the prior, undoing the commit if that fails; or discards them
(:func:`discard_staged`). An interrupted fleet (Ctrl-C, SIGTERM) commits the units finished
by then, each complete, writes no summary or prior, and discards every other staging
folder (a unit stopped while writing leaves none).
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

from kincal.errors import ExportError
from kincal.fleet.unit import STAGING

# an earlier DIR/<unit>, moved aside while the new one takes its name: not a staging folder
# (discard_staged never removes one), and no unit's name (kincal.cli.fleet.unit_names)
OLD = ".replaced-"


@dataclass
class UnitCommit:
    """The units put in place by :func:`commit_units`: :meth:`undo` takes them out again
    (the earlier folders back under their names), :meth:`done` drops the earlier folders."""

    out_dir: Path
    placed: list[tuple[str, bool]] = field(default_factory=list)  # (unit, an earlier moved)

    def undo(self) -> None:
        """Every placed unit back out (removed), every earlier folder back under its name;
        best effort: one that cannot be undone does not stop the others."""
        for name, had_old in reversed(self.placed):
            final, old = self.out_dir / name, self.out_dir / f"{OLD}{name}"
            try:
                shutil.rmtree(final)
                if had_old:
                    os.replace(old, final)
            except OSError:
                pass
        self.placed.clear()

    def done(self) -> None:
        """The fleet's files are written: the earlier unit folders go."""
        for name, had_old in self.placed:
            if had_old:
                shutil.rmtree(self.out_dir / f"{OLD}{name}", ignore_errors=True)


def commit_units(out_dir, names, overwrite: bool) -> UnitCommit:
    """Put the staged units ``names`` in place under ``out_dir``, all or none: each staging
    folder takes its unit's name (an earlier folder of that name, with ``overwrite``, moved
    aside until :meth:`UnitCommit.done`). ExportError, with every unit undone, if one cannot
    be put in place."""
    commit = UnitCommit(Path(out_dir))
    for name in names:
        final, stage = commit.out_dir / name, commit.out_dir / f"{STAGING}{name}"
        old = commit.out_dir / f"{OLD}{name}"
        moved = False
        try:
            if final.exists() or final.is_symlink():
                if not overwrite:
                    raise ExportError(f"{final} exists; give --overwrite to replace it")
                if old.exists():  # left by a run that was killed here
                    shutil.rmtree(old)
                os.replace(final, old)
                moved = True
            os.replace(stage, final)
        except (OSError, ExportError) as e:
            if moved and not final.exists():  # this unit's earlier folder back first
                os.replace(old, final)
            commit.undo()
            reason = e.strerror or e if isinstance(e, OSError) else e
            raise ExportError(f"{final}: could not put the unit's files in place ({reason}); "
                              "no unit's files were put in place, the earlier ones are "
                              "kept") from None
        commit.placed.append((name, moved))
    return commit


def discard_staged(out_dir) -> None:
    """Remove every staging folder under ``out_dir`` (units that waited for a fleet that
    failed, or were stopped midway)."""
    out = Path(out_dir)
    if out.is_dir():
        for stage in out.glob(f"{STAGING}*"):
            shutil.rmtree(stage, ignore_errors=True)
