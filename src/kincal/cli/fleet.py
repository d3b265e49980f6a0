"""``kincal fleet``: calibrate every unit of a fleet of one robot model on a distributed
engine (Dask), write each unit's outputs under DIR/<unit>/, the fleet summary and the fleet
prior DIR/FLEET.json (:mod:`kincal.fleet`): all of them once the fleet has succeeded (two
units calibrated, a prior learnt), none if it fails; interrupted, the units finished by then
(each complete) and nothing else."""

from __future__ import annotations

import contextlib
import os
import sys
from dataclasses import dataclass, replace
from pathlib import Path

from kincal.cli.options import (Chain, Inputs, add_common, add_gate_overrides, add_model,
                                add_overwrite, group, typed)
from kincal.errors import DataError, OptionError

SUMMARY_JSON, SUMMARY_HTML, PRIOR = "FLEET_SUMMARY.json", "fleet.html", "FLEET.json"


def register(subparsers) -> None:
    p = subparsers.add_parser("fleet", help="calibrate every unit of a fleet of one robot model "
                              "and learn the fleet prior (FLEET.json)")
    add_common(p, data=False)
    from kincal.cli.options import add_joint_columns, add_units

    group(p, "inputs").add_argument("data", nargs="+", metavar="DATA.csv",
                                    help="one data file per unit (the unit is named after the "
                                         "file)")
    add_units(p)
    add_joint_columns(p)
    add_model(p)
    g = group(p, "model and penalty")
    g.add_argument("--lambda", dest="lam", default="evidence",
                   help="as in kincal calibrate: 'evidence' (default here: what a unit's data "
                        "cannot see stays at nominal instead of drifting into the prior), "
                        "'auto', 'cv' or a value >= 0")
    g.add_argument("--fix", nargs="+", default=[], metavar="NAME",
                   help="parameters held nominal in every unit (names or quoted patterns)")
    g.add_argument("--hierarchical", type=int, default=0, metavar="ROUNDS",
                   help="learn the prior by this many rounds of the hierarchical fit "
                        "(empirical Bayes over the units' data jointly; for fleets measured "
                        "in small volumes); 0 (default): each unit alone")
    e = group(p, "engine")
    e.add_argument("--workers", type=int, default=1, metavar="N",
                   help="worker processes of the local Dask cluster (default 1; at most 4 per "
                        "CPU)")
    e.add_argument("--scheduler", metavar="ADDRESS",
                   help="a running Dask scheduler (tcp://host:8786) instead of a local cluster")
    o = group(p, "outputs")
    o.add_argument("--out-dir", required=True, metavar="DIR",
                   help="DIR/<unit>/ (corrected.urdf, FRAMES.json, REPORT.json), "
                        "DIR/FLEET.json, DIR/FLEET_SUMMARY.json, DIR/fleet.html")
    add_overwrite(p)
    add_gate_overrides(p, "a unit's outputs")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Fleet:
    """The options of ``kincal fleet``, typed."""

    chain: Chain
    inputs: Inputs  # the reading options (files: every unit's file)
    model: str | None
    lam: str
    fix: tuple[str, ...]
    hierarchical: int
    workers: int
    scheduler: str | None
    out_dir: str
    overwrite: bool
    accept_implausible: bool
    accept_unconverged: bool
    quiet: bool
    json: bool = False
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def unit_names(files) -> list[str]:
    """Each file's unit name (its folder under DIR): its stem, made unique with its
    position when stems repeat (``x/a.csv y/a.csv`` -> ``a-1 a-2``), and further when that
    is another file's stem (``a-2.csv`` beside them: ``a-2-2``); names equal but for case
    count as one (a case-insensitive file system has one folder for both). Two units in one
    folder would replace each other's files, and the summary would count one twice. A name
    the fleet's own files or staging folders take is refused."""
    from kincal.fleet.folders import OLD
    from kincal.fleet.unit import STAGING

    stems = [Path(f).stem for f in files]
    keys = [s.casefold() for s in stems]
    unique = {k for k in keys if keys.count(k) == 1}
    names: list[str] = []
    taken = set(unique)
    for i, (stem, key) in enumerate(zip(stems, keys)):
        name = stem
        if key not in unique:
            name, n = f"{stem}-{i + 1}", 1
            while name.casefold() in taken:
                n += 1
                name = f"{stem}-{i + 1}-{n}"
            taken.add(name.casefold())
        names.append(name)
    reserved = {n.casefold() for n in (PRIOR, SUMMARY_JSON, SUMMARY_HTML)}
    for f, name in zip(files, names):
        if name.casefold() in reserved or name.startswith((STAGING, OLD)) \
                or name in ("", ".", ".."):
            raise OptionError(f"{f}: its unit would be DIR/{name}, a name the fleet's own files "
                              f"or staging folders ({STAGING}*, {OLD}*) take; rename the data "
                              "file")
    return names


def repeated_units(files) -> None:
    """Refuse one unit's data given twice (the same file, or two files of the same bytes):
    the fleet would count it as two units, and its prior's scatter would shrink toward that
    unit's deviations. Files that cannot be read are left to the unit (FAILED, reported)."""
    from kincal.input_files import same_files

    same = same_files(files)
    if same is not None:
        raise OptionError(f"{same[1]} {same[2]}: one unit's data given twice would count as "
                          "two units and shrink the fleet's scatter; give each unit's file once")


def run(args) -> int:
    from kincal.cli.console import say_and_write, summary_lines
    from kincal.cli.checks import lambda_value
    from kincal.cli.options import xacro_args
    from kincal.export.outputs import File
    from kincal.cli.checks import check_outputs
    from kincal.fleet import UnitJob, calibrate_fleet
    from kincal.fleet.folders import commit_units, discard_staged
    from kincal.fleet.unit import FRAMES, REPORT, URDF
    unit_files = (URDF, FRAMES, REPORT)
    from kincal.identification.options import CalibrationOptions

    inputs = typed(Inputs, args, files=tuple(args.data))
    c = typed(Fleet, args, chain=Chain.of(args), inputs=inputs)
    options = CalibrationOptions(model=c.model, lam=lambda_value(c.lam), fix=c.fix,
                                 tool_guess=inputs.tool_guess).validated()
    robot = c.chain.load()  # a bad robot or chain: one line, before any worker starts
    out = Path(c.out_dir)
    names = unit_names(inputs.files)
    fixed = [out / n for n in (PRIOR, SUMMARY_JSON, SUMMARY_HTML)]
    protect = check_outputs(robot, fixed, overwrite=c.overwrite, inputs=inputs.files,
                            dirs=[c.out_dir])  # as given: Path("") is the current folder
    taken = [n for n in names if (out / n).exists()]
    if taken and not c.overwrite:
        raise OptionError(f"{out}: unit folders exist ({', '.join(taken[:5])}); give "
                          "--overwrite to replace them")
    for n in taken:  # --overwrite replaces a unit's folder whole: only if it holds no more
        extra = sorted(p.name for p in (out / n).iterdir()) if (out / n).is_dir() else [n]
        extra = [e for e in extra if e not in unit_files]  # than a unit's files, none read
        extra += [Path(f).name for f in (robot.source, *inputs.files) if f and
                  Path(f).expanduser().resolve().parent == (out / n).resolve()
                  and Path(f).name not in extra]
        if extra:
            raise OptionError(f"{out / n}: holds files a fleet unit does not write "
                              f"({', '.join(extra[:3])}{', ...' if len(extra) > 3 else ''}), "
                              "which replacing the unit's folder would delete; move them or "
                              "choose another --out-dir")
    repeated_units(inputs.files)
    # no folder made here: the one writer makes DIR with the first file written into it (a
    # unit's staging folder, or the summary's), so a run that fails before leaves nothing
    # behind; the units share it and never remove it, the command does if the run leaves it
    # empty. The units' files wait in their staging folders for the fleet's outcome
    # (kincal.fleet.folders): a fleet that fails writes nothing and replaces nothing.
    made = not out.exists()
    # absolute paths: a worker of a running scheduler (--scheduler) has a cwd of its own
    from kincal.descriptions import portable

    chain = replace(c.chain, robot=portable(c.chain.robot))
    jobs = [UnitJob(n, os.path.abspath(f), chain.load,
                    replace(inputs, files=(os.path.abspath(f),)).read_sets, options,
                    os.path.abspath(out), c.accept_implausible, c.accept_unconverged,
                    c.overwrite, c.command_line or None, xacro_args(chain.xacro_arg))
            for n, f in zip(names, inputs.files)]
    finished: list[str] = []
    kept: list[str] = []  # the last round's calibrated units: their files staged, complete

    def progress(done, total, outcome):
        finished.append(outcome.name)
        if done > len(jobs) * c.hierarchical and outcome.status == "calibrated":
            kept.append(outcome.name)
        if not c.quiet:
            print(f"  unit {done}/{total}: {outcome.name} {outcome.status}", file=sys.stderr,
                  flush=True)

    def discard():
        discard_staged(out)  # no unit's files are left behind, staged or half written
        _remove_if_empty(out, made)  # made by a unit's staging

    try:
        summary = calibrate_fleet(robot, jobs, c.workers, c.scheduler, c.hierarchical,
                                  progress)
    except BaseException as exc:  # Ctrl-C, SIGTERM: the workers are stopped by now
        from kincal.cli.console import Terminated

        if not isinstance(exc, (KeyboardInterrupt, Terminated)):
            discard()
            raise
        signal, code = ("SIGINT", 130) if isinstance(exc, KeyboardInterrupt) else ("SIGTERM", 143)
        print(f"kincal: error: interrupted ({signal}) after {len(finished)} of the "
              f"{len(jobs) * (c.hierarchical + 1)} unit calibrations: "
              f"{_keep_finished(out, kept, names, c.overwrite, discard)}", file=sys.stderr)
        return code
    if summary.prior is None:  # the fleet failed: its units' files are no result of it
        discard()
        raise DataError(_failed(summary.units, out))
    status = [u.status for u in summary.units]
    gate = (f"each unit's own gate: {status.count('calibrated')} calibrated, "
            f"{status.count('refused')} refused, {status.count('failed')} failed of "
            f"{len(status)} units (the prior is learnt from the calibrated ones)")
    units = None
    try:  # the units put in place, then the fleet's files; any failure: none of them
        files = [File(out / SUMMARY_JSON, "json", summary.as_dict()),
                 File(out / SUMMARY_HTML, "html", summary.html()),
                 File(out / PRIOR, "json", summary.prior.as_dict())]
        units = commit_units(out, [u.name for u in summary.units if u.status == "calibrated"],
                             c.overwrite)
        say_and_write(files, lambda written: summary_lines(
            c.json, [summary.table()], {"command": "fleet", **summary.as_dict()}, written),
            provenance=c.chain.provenance(robot, inputs.files, c.command_line,
                                          verdict="per unit", gate=gate),
            overwrite=c.overwrite, protect=protect, dirs=[out])
        units.done()  # the earlier unit folders replaced go
    except BaseException:
        if units is not None:
            units.undo()  # the summary could not be written: no unit's files either
        discard()
        raise
    return 0


def _keep_finished(out: Path, names: list[str], units: list[str], overwrite: bool,
                   discard) -> str:
    """An interrupted fleet: the units finished (their staged files complete) put in place,
    every other staged or half-written unit discarded; what was kept, as a clause (naming
    an earlier run's files left beside them: its prior, the folders of this run's other
    ``units``). The fleet's own files (summary, prior) need every unit: none is written."""
    from kincal.errors import ExportError
    from kincal.fleet.folders import commit_units

    older = [PRIOR] * (out / PRIOR).exists() + [u for u in units if u not in names
                                                 and (out / u).exists()]
    stale = (f"; an earlier run's {', '.join(older[:4])}{' ...' if len(older) > 4 else ''} "
             f"in {out} left as they were" if older else "")
    try:
        commit_units(out, names, overwrite).done()
    except ExportError as e:
        names = []
        stale = f" ({e}){stale}"
    finally:
        discard()
    if not names:
        return f"nothing was written (no unit's files, no fleet prior or summary){stale}"
    listed = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
    return (f"the {len(names)} unit(s) finished are in place in {out} ({listed}), each "
            f"complete; the others and the fleet prior and summary were not written{stale}")


def _failed(units, out: Path) -> str:
    """The error of a fleet with fewer than two units calibrated: each unit's outcome."""
    calibrated = sum(u.status == "calibrated" for u in units)
    stale = (f"; {out / PRIOR} is an earlier run's, left as it was"
             if (out / PRIOR).exists() else "")
    groups: dict[tuple[str, str], list[str]] = {}  # one reason said once: 200 units failing
    for u in units:  # alike (an unknown --fix name) make one clause, not 200 copies
        groups.setdefault((u.status, u.message or ""), []).append(u.name)
    each = "; ".join(f"{_some(names)}: {status}" + (f" ({message})" if message else "")
                     for (status, message), names in groups.items())
    return (f"fewer than 2 of the {len(units)} units were calibrated ({calibrated}): a fleet "
            f"prior needs 2, and nothing was written (no unit's files, no summary){stale}. "
            f"Units: {each}")


def _some(names: list[str], most: int = 5) -> str:
    """Unit names as a list, the first ``most`` of a long one and how many more."""
    more = f" and {len(names) - most} more" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def _remove_if_empty(out: Path, made: bool) -> None:
    """Remove the fleet's folder if this run made it and it is empty: the units make it as
    a shared folder, which none of them removes (another may be writing into it), so that a
    run that ends without a file in it leaves no empty folder behind."""
    if made and out.is_dir() and not any(out.iterdir()):
        with contextlib.suppress(OSError):
            out.rmdir()

