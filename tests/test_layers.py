"""The layering of the package, checked: no import cycle between modules, no module importing
a floor above its own (the floor order below), no module over 500 lines, and each
sub-package's public face in ``__all__``.

Floors, lowest first (a module imports its own floor or lower):
errors, rotations and the input readers -> models, frames_file, tilts_in_urdf, urdf_origins ->
measurements, compensation -> robot -> identification -> planning, export -> experiments ->
cli. Imports inside ``if TYPE_CHECKING:`` are for annotations only and do not count."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "src" / "kincal"
FLOORS = [
    {"kincal", "errors", "lazy", "rotations", "input_files", "descriptions", "xacro_source",
     "urdf_source"},
    {"models", "frames_file", "tilts_in_urdf", "urdf_origins"},
    {"measurements", "compensation"},
    {"robot", "collision", "gravity"},
    {"identification"},
    {"planning", "export"},
    {"experiments", "fleet"},
    {"cli", "__main__"},
]
MAX_LINES = 500


def _modules() -> dict[str, Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = list(p.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def _lazy_names() -> dict[str, dict[str, str]]:
    """{package: {public name: module defining it}} of the names the packages import on
    first use: the root's ``_LAZY`` dict, each sub-package's ``lazy_names(__name__, {...})``
    (module names relative to the package). ``from kincal import calibrate`` imports
    kincal.identification.problem as surely as naming it does."""
    out: dict[str, dict[str, str]] = {}
    for package, path in MODULES.items():
        if path.name != "__init__.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if (isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict)
                    and any(isinstance(t, ast.Name) and t.id == "_LAZY" for t in node.targets)):
                out[package] = _constant(node.value)
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                  and node.func.id == "lazy_names"):
                out[package] = {k: f"{package}.{v}"
                                for k, v in _constant(node.args[1]).items()}
    return out


def _constant(node: ast.expr) -> dict:
    """The value of a dict display of constants (``**{n: "m" for n in (...)}`` included)."""
    return eval(compile(ast.Expression(node), "<lazy names>", "eval"), {"__builtins__": {}})


LAZY = _lazy_names()


def _imports(path: Path, module: str = "") -> set[str]:
    """Every kincal module ``path`` (the module ``module``) imports: function-level imports
    included, relative ones resolved, a package's lazily imported names (:func:`_lazy_names`)
    to the modules defining them."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(n) for n in ast.walk(node))
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    out = set()
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # from .x import y, from .. import z: relative to the package
                up = package[:len(package) - (node.level - 1)]
                base = ".".join(up + ([node.module] if node.module else []))
            out.add(base)
            for a in node.names:
                out.add(f"{base}.{a.name}")
                out.add(LAZY.get(base, {}).get(a.name, base))
    return {m for m in out if m in MODULES}


def _area(module: str) -> str:
    parts = module.split(".")
    return "kincal" if len(parts) == 1 else parts[1]


def _floor(module: str) -> int:
    area = _area(module)
    for k, names in enumerate(FLOORS):
        if area in names:
            return k
    raise AssertionError(f"{module}: its area {area!r} has no floor in tests/test_layers.py")


GRAPH = {m: _imports(p, m) - {m} for m, p in MODULES.items()}


def test_every_module_has_a_floor():
    for m in MODULES:
        _floor(m)


def test_no_module_imports_a_floor_above_its_own():
    upward = [f"{m} (floor {_floor(m)}) imports {d} (floor {_floor(d)})"
              for m, deps in sorted(GRAPH.items()) for d in sorted(deps)
              if _area(d) != "kincal" and _floor(d) > _floor(m)]
    assert not upward, "\n".join(upward)


def test_no_import_cycle():
    """Tarjan's strongly connected components over the module graph: none larger than one."""
    index, low, stack, on, cycles = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            # a package's __init__ re-exporting its own modules is not a cycle of ideas
            inner = [c for c in comp if MODULES[c].name != "__init__.py"]
            if len(comp) > 1 and len(inner) > 1:
                cycles.append(sorted(comp))

    for v in sorted(GRAPH):
        if v not in index:
            visit(v)
    assert not cycles, f"import cycles: {cycles}"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_module_over_500_lines(module):
    n = len(MODULES[module].read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"{module} has {n} lines: split it along a seam you can name"


def test_every_subpackage_names_its_public_face():
    for init in sorted(ROOT.glob("*/__init__.py")):
        if init.parent.name == "urdf":
            continue
        tree = ast.parse(init.read_text(encoding="utf-8"))
        names = [t.id for node in tree.body if isinstance(node, (ast.Assign, ast.AnnAssign))
                 for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
                 if isinstance(t, ast.Name)]
        assert "__all__" in names, f"{init.parent.name}/__init__.py has no __all__"


def test_the_checks_catch_a_violation(tmp_path):
    """The floor check itself: a measurements module importing identification is upward."""
    assert _floor("kincal.measurements.point") < _floor("kincal.identification.problem")
    assert _floor("kincal.identification.result") < _floor("kincal.export.outputs")
    # the import forms the graph must see: a package's lazy names (the root's too) and
    # relative imports resolve to the modules defining them (all three were missed)
    for i, line in enumerate(("from kincal import CalibrationProblem",
                              "from kincal.identification import CalibrationProblem",
                              "from ..identification.problem import CalibrationProblem",
                              "def f():\n    from ..identification import problem")):
        fake = tmp_path / f"fake{i}.py"
        fake.write_text(line + "\n")
        assert "kincal.identification.problem" in _imports(fake, "kincal.measurements.fake")
    init = tmp_path / "__init__.py"
    init.write_text("from .problem import calibrate\n")
    assert _imports(init, "kincal.identification") == {"kincal.identification.problem"}
