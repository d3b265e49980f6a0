"""``kincal analyze``: what the data can identify, without solving."""

from __future__ import annotations

from dataclasses import dataclass

from kincal.cli.checks import check_outputs, distinct_inputs
from kincal.cli.options import (AccuracyRequest, Chain, Inputs, add_accuracy_options,
                                add_common, add_kinds, add_model, add_overwrite, group, typed)
from kincal.errors import OptionError


def register(subparsers) -> None:
    p = subparsers.add_parser("analyze", help="what the data can identify, without solving")
    add_common(p, chains=True)
    add_kinds(p)
    add_model(p, allow_all=True, allow_auto=True)
    g = group(p, "model and penalty")
    g.add_argument("--fix", nargs="+", default=[], metavar="NAME",
                   help="parameters held nominal (left out of the analysis): names "
                        "(joint_3.a, tool.z) or quoted shell patterns ('*.d', "
                        "'joint_[456].*')")
    g.add_argument("--backlash", nargs="+", default=[], metavar="JOINT",
                   help="also analyse backlash terms of these joints (see calibrate)")
    g.add_argument("--compliance", nargs="+", default=[], metavar="JOINT",
                   help="also analyse compliance terms of these joints (see calibrate)")
    group(p, "outputs").add_argument("--report",
                                     help="write the identifiability report as JSON")
    add_accuracy_options(p)
    a = group(p, "predicted accuracy")
    a.add_argument("--noise-mm", type=float, default=0.05,
                   help="noise per axis [mm] for the predicted accuracy (least squares on "
                        "these poses; default 0.05)")
    a.add_argument("--accuracy-plot", metavar="MAP.png", help="plot of the accuracy map")
    add_overwrite(p, help="replace existing output files (--report, --accuracy-plot)")
    p.set_defaults(run=run)


@dataclass(frozen=True)
class Analyze:
    """The options of ``kincal analyze``."""

    chain: Chain
    inputs: Inputs
    accuracy: AccuracyRequest
    model: str  # an error model, "auto" (the candidates compared by CV) or "all" (listed)
    fix: tuple[str, ...]
    backlash: tuple[str, ...]
    compliance: tuple[str, ...]
    report: str | None
    noise_mm: float  # [mm] per axis, for the predicted accuracy
    accuracy_plot: str | None
    overwrite: bool
    json: bool = False
    command_line: tuple[str, ...] = ()  # as typed, for the files' provenance


def run(args) -> int:
    from kincal.cli.console import quiet_stdout, say_and_write, summary_lines

    a = typed(Analyze, args, chain=Chain.of(args), inputs=Inputs.of(args),
              accuracy=AccuracyRequest.of(args))
    with quiet_stdout(a.json):  # with --json, stdout holds the JSON alone
        robot, summary, files, protect = _analyze(a)
    say_and_write(files, lambda written: summary_lines(a.json, [], summary, written, wrote=None),
                  provenance=a.chain.provenance(robot, a.inputs.files, a.command_line),
                  overwrite=a.overwrite, protect=protect)
    return 0


def _design_accuracy(a: Analyze, robot, problem):
    """The accuracy map predicted before solving, or None if not asked."""
    if not a.accuracy.asked:
        if a.accuracy_plot:
            raise OptionError("--accuracy-plot needs --accuracy-map or --accuracy-poses")
        return None
    from kincal.planning.accuracy_map import design_accuracy_map

    return design_accuracy_map(problem, a.noise_mm * 1e-3, **a.accuracy.targets(robot))


def _analyze(a: Analyze):
    """Print the analysis; return (robot, the --json summary, the File values to write,
    the paths they must not replace)."""
    import numpy as np

    from kincal.export import report
    from kincal.identification.options import CalibrationOptions
    from kincal.identification.problem import CalibrationProblem
    from kincal.models import MODELS, default_for

    robots = Chain.load_all(a.chain.per_file(len(a.inputs.files)))  # each file's chain
    robot = robots[0]
    several = len({(r.base, r.tip) for r in robots}) > 1
    if several and a.accuracy.asked:
        raise OptionError("--accuracy-map and --accuracy-poses describe one chain; this "
                          "analysis has several (one --base/--tip per file)")
    distinct_inputs(a.inputs.files)
    protect = check_outputs(robot, [a.report, a.accuracy_plot], overwrite=a.overwrite,
                            inputs=(*a.inputs.files, a.accuracy.accuracy_poses))
    sets = a.inputs.read_sets(robots)
    if a.model == "all":  # every model that can describe this chain (these chains)
        tree = several or default_for(robot.geometry) != "complete"
        names = tuple(m for m in MODELS if not (tree and m in ("complete", "mdh")))
    else:
        names = (a.model,)
    if a.model == "all" and a.fix:
        raise OptionError("--model all compares the models as they are: give --fix with one "
                          "model (the parameter names differ between models)")
    problems = {m: CalibrationProblem(robots, sets, CalibrationOptions(
        model=m, fix=a.fix, backlash=a.backlash, compliance=a.compliance,
        tool_guess=a.inputs.tool_guess))
        for m in names}
    problem = problems[names[0]]
    if a.accuracy.asked:  # before the analysis is printed
        from kincal.planning.accuracy_map import require_mappable

        require_mappable(problem.kinds)
    chains = ", ".join(dict.fromkeys(f"{r.base} -> {r.tip}" for r in robots))
    if len(sets) == 1 and problem.kinds[0].kind == "point":
        print(f"{robot.name} ({chains}), {len(sets[0])} poses from {a.inputs.data}")
    else:
        print(f"kincal analysis of {robot.name} ({chains}), error model "
              f"{problem.model_name}: " + ", ".join(
                  f"{km.kind} ({km.data.source}, {km.N} samples)" for km in problem.kinds))
    if problem.model_choice is not None:  # --model auto: the candidates compared, nothing written
        print("\n".join(line[2:] for line in problem.model_choice.lines()))
    idents = {}
    for m, p in problems.items():
        ident = idents[m] = p.analyze()
        if len(names) > 1:
            print(f"\n== model {m}: {p.error_model.describe()}")
        print(ident.summary())
    if problem.kinds[0].kind == "point":
        tools = problem.layout.frames(problem.start(), 0)[6:].reshape(-1, 3)
        for k, tool in enumerate(tools, start=1):
            which = "tool point" if len(tools) == 1 else f"measured point {k}"
            print(f"  {which} (first estimate, tip frame): {np.round(tool * 1e3, 3).tolist()} mm")
    if len(names) > 1:
        _print_comparison(names, problems, idents)
    amap = _design_accuracy(a, robot, problem)
    if amap is not None:
        print(amap.summary())
    from kincal.export.outputs import File

    files = []
    as_json = (report.identifiability_dict(idents[names[0]]) if len(names) == 1 else
               {m: report.identifiability_dict(i) for m, i in idents.items()})
    content = dict(as_json)
    if amap is not None:
        content["accuracy_map"] = amap.as_dict()
    if a.report:
        files.append(File(a.report, "json", content))
    if a.accuracy_plot and amap is not None and len(amap.std):
        from kincal.export.diagnostic_plots import plot_accuracy_map

        files.append(File(a.accuracy_plot, "png",
                          lambda fields: plot_accuracy_map(amap, source=fields)))
    summary = {"command": "analyze", "robot": str(robot.source),
               "data": [str(f) for f in a.inputs.files], "model": problem.model_name,
               "model_choice": (None if problem.model_choice is None
                                else problem.model_choice.as_dict()),
               **({"identifiability": as_json} if len(names) == 1 else {"models": as_json}),
               "accuracy_map": None if amap is None else amap.as_dict()}
    return robot, summary, files, protect


def _print_comparison(names, problems, idents) -> None:
    print("\ncomparison (identified kinematic parameters; '+' what a model identifies that "
          "mdh cannot express):")
    mdh_kept = set(idents["mdh"].kept) if "mdh" in idents else set()
    for m in names:
        p = problems[m]
        kin = [n for n in idents[m].kept if n in set(p.layout.kinematic_names)]
        extra = [n for n in kin if n not in mdh_kept and m == "complete"]
        line = (f"  {m:<10} {len(kin):3d} of {p.layout.n_kinematic:3d} kinematic parameters "
                "identified")
        more = idents[m].rank - idents["mdh"].rank if "mdh" in idents else 0
        if extra:
            line += f"  (+ {', '.join(extra)})"
        elif m == "placement" and more > 0:  # its span holds mdh's; its names are others
            line += f"  (+ {more} directions mdh cannot express)"
        print(line)
