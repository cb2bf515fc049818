"""The layers hold: what may import what (docs/architecture.md), read from the code itself.

Every import in the product packages is read with ``ast`` (module-level and inside functions,
but not ``if TYPE_CHECKING:`` blocks, which never run), so a rule broken anywhere fails here.
The vehicle side stays light too: the executive never loads xarray, scipy or numba.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("planner", "executive", "vehicle_sim")
MAX_MODULE_LINES = 800
# The bottom layer's whole world: the standard library and these.
CONTRACT_THIRD_PARTY = frozenset({"numpy", "yaml"})
HEAVY = ("xarray", "scipy", "numba", "netCDF4", "pyproj", "matplotlib", "tqdm")


@dataclass(frozen=True)
class Import:
    importer: str  # dotted module doing the import
    target: str  # dotted module imported (a package's submodule when a name is one)
    names: tuple[str, ...]  # names taken from it (empty for ``import x``)
    line: int


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES: dict[str, Path] = {
    _module_name(p): p for pkg in PACKAGES for p in sorted((REPO / pkg).rglob("*.py"))
}


def _type_checking_only(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _walk_runtime(tree: ast.AST):  # type: ignore[no-untyped-def]
    """Every node that can run: ``if TYPE_CHECKING:`` bodies are skipped."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _type_checking_only(child):
                stack.extend(child.orelse)
                continue
            stack.append(child)


def _imports(module: str, path: Path) -> list[Import]:
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[Import] = []
    for node in _walk_runtime(tree):
        if isinstance(node, ast.Import):
            out.extend(Import(module, a.name, (), node.lineno) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in MODULES:  # ``from planner.contract import table``: the module itself
                    out.append(Import(module, sub, (), node.lineno))
                else:
                    out.append(Import(module, base, (alias.name,), node.lineno))
    return out


IMPORTS: list[Import] = [imp for mod, path in MODULES.items() for imp in _imports(mod, path)]


def _ours(target: str) -> bool:
    return target.split(".")[0] in PACKAGES


def _where(imp: Import) -> str:
    return f"{MODULES[imp.importer].relative_to(REPO)}:{imp.line} imports {imp.target}"


def _in(module: str, package: str) -> bool:
    return module == package or module.startswith(package + ".")


def test_the_executive_imports_only_the_contract_from_the_planner_and_nothing_from_the_simulator():
    broken = [_where(i) for i in IMPORTS if _in(i.importer, "executive") and _ours(i.target)
              and not (_in(i.target, "executive") or _in(i.target, "planner.contract") or i.target == "planner")]
    assert broken == [], "the executive may import planner.contract only:\n" + "\n".join(broken)


def test_the_simulator_imports_nothing_from_the_executive():
    broken = [_where(i) for i in IMPORTS if _in(i.importer, "vehicle_sim") and _in(i.target, "executive")]
    assert broken == [], "\n".join(broken)


def test_the_contract_imports_only_itself_the_standard_library_numpy_and_yaml():
    stdlib = sys.stdlib_module_names
    broken = []
    for i in IMPORTS:
        if not _in(i.importer, "planner.contract"):
            continue
        top = i.target.split(".")[0]
        ok = _in(i.target, "planner.contract") or i.target == "planner" or top in stdlib or top in CONTRACT_THIRD_PARTY
        if not ok:
            broken.append(_where(i))
    assert broken == [], "planner.contract is the bottom layer:\n" + "\n".join(broken)


PLANNING_CORE = ("planner.forecast", "planner.grid", "planner.paper", "planner.physical", "planner.pipeline",
                 "planner.cluster")


def test_the_planning_core_imports_no_tool_above_it():
    """Forecasts, grid, models and pipeline serve the shore tools, the CLI and the simulator, never the reverse."""
    above = ("planner.shore", "planner.cli", "executive", "vehicle_sim")
    broken = [_where(i) for i in IMPORTS if any(_in(i.importer, p) for p in PLANNING_CORE)
              and any(_in(i.target, a) for a in above)]
    assert broken == [], "\n".join(broken)


def test_the_shore_tools_and_the_simulator_do_not_import_the_cli():
    broken = [_where(i) for i in IMPORTS if (_in(i.importer, "planner.shore") or _in(i.importer, "vehicle_sim")
                                           or _in(i.importer, "executive")) and _in(i.target, "planner.cli")]
    assert broken == [], "\n".join(broken)


def test_no_import_circles():
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for i in IMPORTS:
        if i.target in MODULES and i.target != i.importer:
            graph[i.importer].add(i.target)
    # Tarjan's strongly connected components; any with more than one module is a circle.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
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
                circles.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    assert circles == [], f"modules that import each other: {circles}"


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _private_attributes(module: str, path: Path) -> list[str]:
    """``other._name`` where ``other`` is one of our modules bound by an import in ``module``."""
    tree = ast.parse(path.read_text())
    bound: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            for alias in node.names:
                if f"{node.module}.{alias.name}" in MODULES:
                    bound[alias.asname or alias.name] = f"{node.module}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in MODULES and alias.asname:
                    bound[alias.asname] = alias.name
    return [f"{path.relative_to(REPO)}:{node.lineno} uses {bound[node.value.id]}.{node.attr}"
            for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
            and node.value.id in bound and _private(node.attr)]


def test_no_private_name_is_imported_from_another_module():
    broken = [f"{_where(i)}: {name}" for i in IMPORTS if _ours(i.target) for name in i.names if _private(name)]
    broken += [use for module, path in MODULES.items() for use in _private_attributes(module, path)]
    assert broken == [], "make the name public where it belongs, or move it:\n" + "\n".join(broken)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_module_is_over_the_line_limit(module):
    lines = len(MODULES[module].read_text().splitlines())
    assert lines <= MAX_MODULE_LINES, f"{MODULES[module].relative_to(REPO)}: {lines} lines; split it along a noun"


def test_importing_changes_no_environment_variable():
    """pymavlink's habit of setting MAVLINK20 at import is the one we avoid: no module writes os.environ."""
    broken = []
    for module, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            target = None
            if isinstance(node, (ast.Assign, ast.AugAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                target = next((t for t in targets if isinstance(t, ast.Subscript)
                               and ast.unparse(t.value) == "os.environ"), None)
            elif isinstance(node, ast.Call) and ast.unparse(node.func) in (
                    "os.environ.setdefault", "os.environ.update", "os.putenv", "os.environ.pop"):
                target = node
            if target is not None:
                broken.append(f"{path.relative_to(REPO)}:{node.lineno}")
    assert broken == [], "modules that change the environment:\n" + "\n".join(broken)


def test_the_rules_see_a_broken_rule(tmp_path):
    """The reader finds a lazy import inside a function and skips TYPE_CHECKING blocks."""
    path = tmp_path / "probe.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from planner.cli import main\n"
                    "def f():\n    from vehicle_sim.dynamics import step\n    from executive.helm import _due\n")
    MODULES["executive.probe"] = path
    try:
        found = _imports("executive.probe", path)
    finally:
        del MODULES["executive.probe"]
    assert [(i.target, i.names) for i in sorted(found, key=lambda i: i.line)] == [("typing", ("TYPE_CHECKING",)),
                                                     ("vehicle_sim.dynamics", ("step",)),
                                                     ("executive.helm", ("_due",))]


def _heavy_after(code: str) -> str:
    """The heavy packages loaded by ``code`` in a fresh interpreter, comma-separated."""
    probe = f"import sys\n{code}\nprint(','.join(m for m in {HEAVY!r} if m in sys.modules))\n"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True,
                          cwd=REPO).stdout.strip()


def test_executive_import_path_has_no_heavy_packages():
    loaded = _heavy_after(
        "import executive.loop, executive.cli, executive.recorder, executive.helm, executive.mavlink_bridge\n"
        "import planner.contract.mission  # read by `lrauv exec --mission`"
    )
    assert loaded == "", f"the executive imported {loaded}"


def test_lrauv_exec_help_loads_nothing_heavy():
    loaded = _heavy_after("from planner.cli import build_parser\nbuild_parser().parse_args(['exec', '--table', 'x.lrpt'])")
    assert loaded == "", f"`lrauv exec` argument parsing imported {loaded}"
