"""``kincal demo``: the paper's experiment, simulated at a small size."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from kincal.cli.options import add_overwrite, group, typed

DEMO_DIR = "kincal-demo"


def register(subparsers) -> None:
    p = subparsers.add_parser("demo", help="the paper's experiment, simulated at a small size")
    group(p, "outputs").add_argument("--out", default=DEMO_DIR,
                                     help=f"output directory (default {DEMO_DIR})")
    add_overwrite(p, help="replace the files of an earlier demo in that directory")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Demo:
    out: str  # output folder
    overwrite: bool
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def run(args) -> int:
    d = typed(Demo, args)
    from kincal.experiments.paper_report import demo

    print("kincal demo: the paper's experiment on a simulated EC66 (one seed, small size)",
          flush=True)  # a stdout that cannot take it fails here, before any work
    from kincal.export.provenance import Provenance
    from kincal.robot import Robot

    prov = Provenance.of_run(Robot.load("ec66"), (), command=d.command_line or None,
                             gate="the demo's calibrations are compared with the planted "
                                  "truth; no corrected robot is written")
    s = demo(Path(d.out), progress=lambda message: print(f"  {message}", flush=True),
             provenance=prov)
    print(f"validation in the 400 mm cube, mean position error [mm] (lambda = {s.lam:.3g}):")
    for label, value in (("before calibration", s.before_validation_mean_mm),
                         ("LS + R-test (20 mm cube)", s.ls_rtest_validation_mean_mm),
                         ("L2 + R-test (20 mm cube)", s.l2_rtest_validation_mean_mm),
                         ("LS + laser tracker", s.ls_tracker_validation_mean_mm)):
        print(f"  {label:<28} {value:8.3f}")
    print(f"wrote {len(s.files)} files to {s.out_dir}/ in {s.elapsed_s:.1f} s:")
    for f in s.files:
        print(f"  {f}")
    return 0
