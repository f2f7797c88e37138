"""The architecture of README.md ("Architecture"), checked on the source with ``ast``.

* Layers import only downward: fmu_src never imports harness; harness.data never imports sim, analysis,
  report or the top (pipeline, jobs, outputs, cli); harness.sim never imports analysis, report or the top;
  harness.analysis never imports report or the top; harness.report never imports the top.
* Inside harness.analysis, subpackages by concern, bottom to top: core (shared numerics), identification,
  then validation, uncertainty and diagnosis side by side (discovery, the term library and selector, under
  the diagnosis alone), design; each imports only downward, and no analysis module lies outside them.
* No import cycle among the project's modules (imports inside functions count).
* No module over 600 lines; no function with more than 8 parameters (keyword-only ones count; ``self``
  and ``cls`` do not).
* No test imports or uses a private name (one leading underscore) of another module.

Every check is also run on planted offences (``test_the_checks_can_fail``), so that each can fail.
"""
from __future__ import annotations

import ast
import re
import sys
from functools import lru_cache
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("fmu_src", "harness")
TOP_MODULES = ("build_fmu",)                     # project modules at the repository root
MAX_LINES = 600
MAX_PARAMS = 8

TOP = ("harness.pipeline", "harness.jobs", "harness.jobs_control", "harness.jobs_design", "harness.outputs", "harness.cli", "harness.chain",
       "harness.chain_control", "harness.api")
# layer -> what it must never import
FORBIDDEN = {
    "fmu_src": ("harness",),
    "harness.data": ("harness.sim", "harness.analysis", "harness.report") + TOP,
    "harness.sim": ("harness.analysis", "harness.report") + TOP,
    "harness.analysis": ("harness.report",) + TOP,
    "harness.control": ("harness.report",) + TOP,
    "harness.report": TOP,
}

# harness.analysis's subpackages, bottom to top: core (shared numerics), identification, then validation,
# uncertainty and diagnosis side by side (none imports another), design (over uncertainty). Each imports only
# downward (and harness.data, harness.sim, fmu_src); every analysis module but its __init__ is in one of them.
ANALYSIS = "harness.analysis"
FORBIDDEN_IN_ANALYSIS = {
    "core": ("identification", "validation", "uncertainty", "discovery", "diagnosis", "design"),
    "identification": ("validation", "uncertainty", "discovery", "diagnosis", "design"),
    "validation": ("uncertainty", "discovery", "diagnosis", "design"),
    "uncertainty": ("validation", "discovery", "diagnosis", "design"),
    # discovery (the term library and the selector) lies under the diagnosis that runs it: it sees the fits only
    # through callables, so it imports none of the diagnosis's modules
    "discovery": ("identification", "validation", "uncertainty", "diagnosis", "design"),
    "diagnosis": ("validation", "uncertainty", "design"),
    "design": ("validation", "diagnosis", "discovery"),
}
FORBIDDEN.update({f"{ANALYSIS}.{sub}": tuple(f"{ANALYSIS}.{x}" for x in bad) + ("harness.report",) + TOP
                  for sub, bad in FORBIDDEN_IN_ANALYSIS.items()})


# --------------------------------------------------------------------------- the module graph
def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


@lru_cache(maxsize=None)
def project_modules() -> dict[str, Path]:
    """Every project module (package ``__init__`` under the package's name) -> its file."""
    files = [p for pkg in PACKAGES for p in sorted((REPO / pkg).rglob("*.py"))]
    files += [REPO / f"{m}.py" for m in TOP_MODULES]
    return {_module_name(p): p for p in files if "__pycache__" not in p.parts}


@lru_cache(maxsize=None)
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _is_package(name: str) -> bool:
    return project_modules()[name].name == "__init__.py"


def _resolve(importer: str, node: ast.ImportFrom) -> str:
    """The absolute module a ``from ... import`` names (relative imports resolved against ``importer``)."""
    if not node.level:
        return node.module or ""
    base = importer.split(".")
    if not _is_package(importer):
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(importer: str, tree: ast.AST) -> list[tuple[str, int]]:
    """(imported module, line) of every import anywhere in ``tree``: module level, in functions, in classes."""
    mods = project_modules()
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _resolve(importer, node)
            for a in node.names:
                sub = f"{base}.{a.name}"
                out.append((sub if sub in mods else base, node.lineno))
    return out


def _project_target(name: str) -> str | None:
    """The project module an imported name loads (its longest project-module prefix), or None."""
    mods = project_modules()
    parts = name.split(".")
    for k in range(len(parts), 0, -1):
        cand = ".".join(parts[:k])
        if cand in mods:
            return cand
    return None


@lru_cache(maxsize=None)
def import_graph() -> dict[str, dict[str, int]]:
    """module -> {imported project module: first line}."""
    graph = {}
    for name, path in project_modules().items():
        edges: dict[str, int] = {}
        for imported, line in _imports(name, _tree(path)):
            target = _project_target(imported)
            if target is not None and target != name:
                edges.setdefault(target, line)
        graph[name] = edges
    return graph


def _in(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _rel(path: Path) -> str:
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


def layer_violations(layer: str, graph: dict[str, dict[str, int]] | None = None) -> list[str]:
    out = []
    for mod, edges in sorted((graph or import_graph()).items()):
        if not _in(mod, layer):
            continue
        for target, line in sorted(edges.items()):
            if any(_in(target, f) for f in FORBIDDEN[layer]):
                where = _rel(project_modules()[mod]) if mod in project_modules() else mod
                out.append(f"{where}:{line} imports {target}")
    return out


def analysis_modules_outside_subpackages() -> list[str]:
    """Modules of harness.analysis that are not in one of its layered subpackages (only its ``__init__`` may be)."""
    subs = tuple(f"{ANALYSIS}.{s}" for s in FORBIDDEN_IN_ANALYSIS)
    return sorted(m for m in project_modules() if _in(m, ANALYSIS) and m != ANALYSIS
                  and not any(_in(m, s) for s in subs))


def import_cycles() -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    graph = import_graph()
    index, low, stack, on_stack, comps = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 10 * len(graph) + 100))
    try:
        for v in sorted(graph):
            if v not in index:
                visit(v)
    finally:
        sys.setrecursionlimit(limit)
    return sorted(comps)


# --------------------------------------------------------------------------- size rules
def long_modules() -> list[str]:
    out = []
    for path in project_modules().values():
        n = len(path.read_text(encoding="utf-8").splitlines())
        if n > MAX_LINES:
            out.append(f"{_rel(path)}: {n} lines")
    return sorted(out)


def _n_params(fn: ast.FunctionDef | ast.AsyncFunctionDef, method: bool) -> int:
    a = fn.args
    names = [x.arg for x in a.posonlyargs + a.args]
    if method and names and names[0] in ("self", "cls"):
        names = names[1:]
    return len(names) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


def long_signatures() -> list[str]:
    out = []
    for path in project_modules().values():
        tree = _tree(path)
        methods = {id(f) for c in ast.walk(tree) if isinstance(c, ast.ClassDef) for f in c.body}
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = _n_params(node, id(node) in methods)
                if n > MAX_PARAMS:
                    out.append(f"{_rel(path)}:{node.lineno} {node.name}: {n} parameters")
    return sorted(out)


# --------------------------------------------------------------------------- private names in tests
def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


# attributes with a leading underscore that are public API (namedtuple)
_PUBLIC_UNDERSCORED = {"_replace", "_asdict", "_fields", "_make", "_field_defaults"}


def _leading_text(node: ast.AST) -> str | None:
    """The constant text an expression starts with ("_" for ``"_" + name`` or ``f"_{name}"``)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return _leading_text(node.left)
    if isinstance(node, ast.JoinedStr) and node.values:
        return _leading_text(node.values[0])
    return None


def private_uses(path: Path) -> list[str]:
    """Private names of other modules a test file imports or uses.

    Flags ``from m import _x``; ``obj._x`` on anything but a module from outside the project (the
    test's own helpers are plain names, never attributes); ``getattr``/``setattr``/``hasattr``/
    ``monkeypatch.setattr`` with a name starting with "_"; and dotted strings "pkg.mod._x" naming a
    project module's private name.
    """
    tree = _tree(path)
    outside = set()                  # names bound to modules from outside the project (numpy, fmpy, ...)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                if _project_target(a.name) is None:
                    outside.add(a.asname or a.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom) and not node.level and _project_target(node.module or "") is None:
            outside.update(a.asname or a.name for a in node.names)
    out = []
    for node in ast.walk(tree):
        where = f"{_rel(path)}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, ast.ImportFrom):
            out += [f"{where} imports {a.name} from {node.module}" for a in node.names if _private(a.name)]
        elif isinstance(node, ast.Attribute) and _private(node.attr) and node.attr not in _PUBLIC_UNDERSCORED:
            if not (isinstance(node.value, ast.Name) and node.value.id in outside | {"self", "cls"}):
                out.append(f"{where} uses {ast.unparse(node)}")
        elif isinstance(node, ast.Call) and len(node.args) >= 2:
            fn = ast.unparse(node.func)
            text = _leading_text(node.args[1])
            if fn in ("getattr", "setattr", "hasattr", "delattr", "monkeypatch.setattr") and text is not None \
                    and _private(text):
                out.append(f"{where} uses {ast.unparse(node)}")
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and "." in node.value \
                and " " not in node.value:
            target = _project_target(node.value.rsplit(".", 1)[0])
            if target is not None and _private(node.value.rsplit(".", 1)[1]):
                out.append(f"{where} names {node.value}")
    return out


def project_test_files() -> list[Path]:
    return sorted(p for p in (REPO / "tests").rglob("*.py") if "__pycache__" not in p.parts)


# --------------------------------------------------------------------------- the checks
def test_the_checks_see_the_project():
    mods = project_modules()
    assert {"fmu_src.model", "harness.data.dataset", "harness.sim.simulator",
            "harness.analysis.identification.identify", "harness.report.tables", "harness.pipeline", "harness.cli", "build_fmu"} <= set(mods)
    g = import_graph()
    assert "harness.pipeline" in g["harness.cli"]                    # module-level import
    assert "build_fmu" in g["harness.jobs"]                      # import inside a function
    assert "fmu_src.specs" in g["fmu_src.model"]                     # relative import resolved


def test_the_checks_can_fail(tmp_path):
    """Each detector finds a planted offence (so a passing check means something)."""
    t = ast.parse("from . import specs\ndef f():\n    from .effects import X\n")
    assert [m for m, _ in _imports("fmu_src.model", t)] == ["fmu_src.specs", "fmu_src.effects"]
    f = ast.parse("def f(a, b, c, d, e, f, g, h, *, i): pass\nclass C:\n    def m(self, a, b, c, d, e, f, g, h): pass\n")
    fns = [n for n in ast.walk(f) if isinstance(n, ast.FunctionDef)]
    assert _n_params(fns[0], False) == 9 and _n_params(fns[1], True) == 8
    bad = tmp_path / "test_bad.py"
    bad.write_text("import numpy as np\nfrom harness.sim import batch\nfrom harness.cli import _out_dir\n"
                   "def test(monkeypatch):\n    batch._Group\n    np._NoValue\n    getattr(batch, '_' + 'x')\n"
                   "    monkeypatch.setattr('harness.cli._out_dir', None)\n")
    planted = {"harness.analysis.identification.x": {"harness.analysis.uncertainty.bands": 3},
               "harness.analysis.core.y": {"harness.analysis.identification.analytic": 5},
               "harness.analysis.design.z": {"harness.analysis.uncertainty.run": 7}}
    assert layer_violations("harness.analysis.identification", planted) == [
        "harness.analysis.identification.x:3 imports harness.analysis.uncertainty.bands"]
    assert layer_violations("harness.analysis.core", planted) == [
        "harness.analysis.core.y:5 imports harness.analysis.identification.analytic"]
    assert layer_violations("harness.analysis.design", planted) == []
    found = private_uses(bad)
    assert [s.split(" ", 1)[1] for s in found] == [
        "imports _out_dir from harness.cli", "uses batch._Group", "uses getattr(batch, '_' + 'x')",
        "names harness.cli._out_dir"]


@pytest.mark.parametrize("layer", [
    pytest.param("fmu_src"),
    pytest.param("harness.data"),
    pytest.param("harness.sim"),
    pytest.param("harness.analysis"),
    pytest.param("harness.report"),
] + [pytest.param(f"{ANALYSIS}.{sub}") for sub in FORBIDDEN_IN_ANALYSIS])
def test_layers_import_only_downward(layer):
    assert layer_violations(layer) == []


def test_analysis_modules_are_in_layered_subpackages():
    assert analysis_modules_outside_subpackages() == []


def test_no_import_cycles():
    assert import_cycles() == []


def test_no_module_over_600_lines():
    assert long_modules() == []


def test_no_function_over_8_parameters():
    assert long_signatures() == []


def test_tests_use_no_private_name_of_another_module():
    found = [s for p in project_test_files() if p != Path(__file__).resolve() for s in private_uses(p)]
    assert found == []


def _cached_jit_without_physics_key(files) -> list:
    """Project modules with numba functions cached on disk (``cache=True``) that do not key their cache to the
    physics' sources (``fmu_src.integrator.register_compiled_module``): numba keys a cache entry to the
    defining file alone, so such a module kept functions compiled against an older integrator (its block layout
    included) after an upgrade in place: 9 control tests failed on a stale cache of ``harness.control.mpc``."""
    bad = []
    for f in files:
        text = f.read_text()
        if re.search(r"njit\([^)]*cache\s*=\s*True", text) and f.name != "integrator.py" \
                and "register_compiled_module(__name__, __file__)" not in text:
            bad.append(f.name)
    return bad


def test_every_disk_cached_jit_module_keys_its_cache_to_the_physics(tmp_path):
    files = [f for d in ("harness", "fmu_src") for f in (REPO / d).rglob("*.py")]
    assert _cached_jit_without_physics_key(files) == []
    stale = tmp_path / "stale.py"       # the check can fail
    stale.write_text("import numba\n@numba.njit(cache=True)\ndef f(x):\n    return x\n")
    assert _cached_jit_without_physics_key([stale]) == ["stale.py"]
