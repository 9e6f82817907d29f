"""Import layers of roshan: which modules may import which, read from the source with ``ast`` (nothing is imported).

Layers, lowest first: base modules (config, maps, runtime, episode, checkpoints, io, allocator, ggui, memory,
taichi_patches, reproducible) import no other layer; ``kernels`` (Taichi) imports only base; ``algos`` (torch)
imports only base;
``env`` imports base, kernels and, of the algos, only ``roshan.algos.frozen`` (the planner's frozen fly policy);
``runs``, ``study``, ``tools`` and ``cli`` sit on top. No two roshan modules may import each other, directly or
round a longer cycle, and roshan imports sit at the top of a module, except in ``roshan/cli.py``, which imports its
commands lazily so that ``roshan --help`` stays fast.

The checker is plain functions over a ``{module: [Import, ...]}`` dict, so it is tested on made-up modules too.
"""

import ast
import re
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGE = "roshan"

BASE = ("roshan.config", "roshan.maps", "roshan.runtime", "roshan.episode", "roshan.checkpoints", "roshan.io",
        "roshan.allocator", "roshan.ggui", "roshan.memory", "roshan.taichi_patches", "roshan.reproducible")
UPPER = ("roshan.runs", "roshan.study", "roshan.experiment", "roshan.tools", "roshan.cli")
# (modules under these prefixes, may not import these prefixes, except these modules)
RULES = (
    (("roshan.kernels",), ("roshan.env", "roshan.algos", *UPPER), ()),
    (("roshan.algos",), ("roshan.env", "roshan.kernels", *UPPER), ()),
    (("roshan.env",), ("roshan.algos", *UPPER), ("roshan.algos.frozen",)),
    (BASE, ("roshan.env", "roshan.kernels", "roshan.algos", *UPPER), ()),
)
LAZY_IMPORTS_ALLOWED = ("roshan.cli",)

# Known violations in modules that others are rewriting right now, as (importer, imported module); each entry says
# why it is tolerated. Fix the import, then delete the entry (test_known_violations_still_occur insists).
KNOWN_VIOLATIONS: dict[tuple[str, str], str] = {}


@dataclass(frozen=True)
class Import:
    """One import of a roshan module: the module it loads, the line, and whether it sits inside a function."""

    target: str
    line: int
    local: bool = False


def under(module: str, prefixes: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


# ------------------------------------------------------------------------------------------------ reading


def module_names(root: Path = REPO, package: str = PACKAGE) -> dict[str, Path]:
    """Every module of the package: dotted name -> file (a package is named by its ``__init__.py``)."""
    out = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _resolve(name: str, known: set[str]) -> str | None:
    """The longest known module that ``name`` starts with (``roshan.x.func`` -> ``roshan.x``); None outside."""
    parts = name.split(".")
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in known:
            return ".".join(parts[:n])
    return None


def _from_base(node: ast.ImportFrom, module: str, is_package: bool) -> str:
    """The absolute module a ``from ... import`` reads from; relative levels count from the module's package."""
    if not node.level:
        return node.module or ""
    package = module.split(".") if is_package else module.split(".")[:-1]
    base = package[:len(package) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _targets(node: ast.AST, module: str, is_package: bool, known: set[str]) -> list[str]:
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        base = _from_base(node, module, is_package)
        # `from roshan.runs.report import stats` loads the submodule stats, `from roshan.io import write_gif` io.
        names = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
    return [t for t in (_resolve(n, known) for n in names) if t is not None]


def _imports_in(tree: ast.AST, module: str, is_package: bool, known: set[str]) -> list[Import]:
    out = []

    def visit(node: ast.AST, local: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                out.extend(Import(t, child.lineno, local) for t in _targets(child, module, is_package, known))
            visit(child, local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)))

    visit(tree, False)
    return out


def read_imports(root: Path = REPO, package: str = PACKAGE) -> dict[str, list[Import]]:
    """module -> its imports of other modules of the package. Only import statements count: the Gymnasium entry
    points in ``roshan/env/__init__.py`` are strings (``"roshan.env.single:FlyEnv"``) and load nothing at import."""
    files = module_names(root, package)
    known = set(files)
    return {module: [i for i in _imports_in(ast.parse(path.read_text(), str(path)), module,
                                            path.name == "__init__.py", known) if i.target != module]
            for module, path in files.items()}


# ------------------------------------------------------------------------------------------------ checking


def layer_violations(imports: dict[str, list[Import]]) -> dict[tuple[str, str], str]:
    """(importer, imported) -> what is wrong, for imports that cross the layers the wrong way or sit in a
    function outside ``roshan.cli``."""
    out = {}
    for module, found in imports.items():
        for imp in found:
            for who, banned, allowed in RULES:
                if under(module, who) and under(imp.target, banned) and imp.target not in allowed:
                    out[(module, imp.target)] = f"{module} (line {imp.line}) imports {imp.target}: {who[0]} and " \
                                                f"its layer may not import {', '.join(banned)}"
            if imp.local and module not in LAZY_IMPORTS_ALLOWED:
                out.setdefault((module, imp.target), f"{module} (line {imp.line}) imports {imp.target} inside a "
                                                     "function; roshan imports go at the top of the module")
    return out


def import_cycles(imports: dict[str, list[Import]]) -> list[list[str]]:
    """One cycle (``[a, b, ..., a]``) per group of modules that reach each other through imports."""
    graph = {m: sorted({i.target for i in found}) for m, found in imports.items()}
    return [_cycle_through(group, graph) for group in _strongly_connected(graph)
            if len(group) > 1 or group[0] in graph.get(group[0], ())]


def _strongly_connected(graph: dict[str, list[str]]) -> list[list[str]]:
    """Tarjan's algorithm, iterative (a deep import chain must not hit Python's recursion limit)."""
    index, low, on_stack, stack, groups = {}, {}, set(), [], []
    for start in sorted(graph):
        if start in index:
            continue
        work = [(start, iter(graph.get(start, ())))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is None:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    group = []
                    while True:
                        m = stack.pop()
                        on_stack.discard(m)
                        group.append(m)
                        if m == node:
                            break
                    groups.append(sorted(group))
            elif child not in index:
                index[child] = low[child] = len(index)
                stack.append(child)
                on_stack.add(child)
                work.append((child, iter(graph.get(child, ()))))
            elif child in on_stack:
                low[node] = min(low[node], index[child])
    return groups


def _cycle_through(group: list[str], graph: dict[str, list[str]]) -> list[str]:
    """A shortest cycle from the group's first module back to it, staying inside the group (breadth first)."""
    start, inside = group[0], set(group)
    came_from: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt = []
        for node in frontier:
            for child in graph.get(node, ()):
                if child == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(came_from[path[-1]])
                    return [start, *reversed(path[:-1]), start]
                if child in inside and child not in came_from:
                    came_from[child] = node
                    nxt.append(child)
        frontier = nxt
    raise AssertionError(f"no cycle through {start} in {group}")


# ------------------------------------------------------------------------------------------------ tests


def test_no_import_cycles():
    cycles = import_cycles(read_imports())
    assert not cycles, "import cycles among roshan modules:\n" + "\n".join(" -> ".join(c) for c in cycles)


def test_layers_are_respected():
    found = layer_violations(read_imports())
    new = [why for key, why in sorted(found.items()) if key not in KNOWN_VIOLATIONS]
    assert not new, "imports against the layers:\n" + "\n".join(new)


def test_known_violations_still_occur():
    gone = sorted(set(KNOWN_VIOLATIONS) - set(layer_violations(read_imports())))
    assert not gone, f"fixed, so remove them from KNOWN_VIOLATIONS: {gone}"


def test_every_module_is_read():
    imports = read_imports()
    assert {"roshan", "roshan.cli", "roshan.io", "roshan.kernels.render", "roshan.runs.report.stats"} <= set(imports)
    targets = {i.target for i in imports["roshan.runs.report.plots"]}
    assert targets == {"roshan.io", "roshan.runs.report.episodes", "roshan.runs.report.stats"}
    assert any(i.local for i in imports["roshan.cli"])  # its lazy command imports are seen
    # the Gymnasium entry points in roshan/env/__init__.py are strings, not imports
    assert imports["roshan"] == [] and imports["roshan.env"] == []
    assert [i.target for i in imports["roshan.runtime"]] == ["roshan.allocator", "roshan.taichi_patches"]


def _fake(**modules: list) -> dict[str, list[Import]]:
    """Made-up modules: keyword ``roshan__kernels__a=["roshan.env.b", ("roshan.io", "local")]``."""
    out = {}
    for name, targets in modules.items():
        out[name.replace("__", ".")] = [Import(t, 1) if isinstance(t, str) else Import(t[0], 1, local=True)
                                        for t in targets]
    return out


def test_checker_catches_made_up_violations():
    imports = _fake(roshan__kernels__a=["roshan.env.b", "roshan.maps"],  # kernels -> env: wrong
                    roshan__env__b=["roshan.algos.frozen", "roshan.kernels.a"],  # allowed
                    roshan__env__c=["roshan.algos.ppo"],  # env -> algos other than frozen: wrong
                    roshan__io=["roshan.runs.train"],  # base -> runs: wrong
                    roshan__config__schema=["roshan.maps"],  # base -> base: fine
                    roshan__runs__train=[("roshan.env.b", "local")],  # lazy import outside cli: wrong
                    roshan__cli=[("roshan.runs.train", "local")],  # lazy import in cli: fine
                    roshan__algos__ppo=["roshan.kernels.a"])  # algos -> kernels: wrong
    assert sorted(layer_violations(imports)) == [("roshan.algos.ppo", "roshan.kernels.a"),
                                                 ("roshan.env.c", "roshan.algos.ppo"),
                                                 ("roshan.io", "roshan.runs.train"),
                                                 ("roshan.kernels.a", "roshan.env.b"),
                                                 ("roshan.runs.train", "roshan.env.b")]
    assert import_cycles(imports) == [["roshan.env.b", "roshan.kernels.a", "roshan.env.b"]]
    # A longer cycle: env.b -> kernels.a -> runs.train -> env.b (runs.train's import of env.b is the local one).
    imports["roshan.kernels.a"] = [Import("roshan.runs.train", 2)]
    assert import_cycles(imports) == [["roshan.env.b", "roshan.kernels.a", "roshan.runs.train", "roshan.env.b"]]
    assert import_cycles(_fake(roshan__x=["roshan.x"])) == [["roshan.x", "roshan.x"]]


def test_relative_and_submodule_imports_resolve(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from . import a\n")
    (pkg / "a.py").write_text("from .sub import b\nfrom .sub.b import thing\n\ndef f():\n    from pkg import sub\n")
    (pkg / "sub" / "__init__.py").write_text("from ..a import x\n")
    (pkg / "sub" / "b.py").write_text("from .. import a\nimport pkg.sub\n'pkg.nothing:Here'\n")
    got = {m: sorted((i.target, i.local) for i in found) for m, found in read_imports(tmp_path, "pkg").items()}
    assert got == {"pkg": [("pkg.a", False)],
                   "pkg.a": [("pkg.sub", True), ("pkg.sub.b", False), ("pkg.sub.b", False)],
                   "pkg.sub": [("pkg.a", False)],
                   "pkg.sub.b": [("pkg.a", False), ("pkg.sub", False)]}


def test_the_rooms_that_mixed_trades_stay_small():
    """issue 31: the fire model without its layout policy, cell records and particle passes; the training loop
    without its learners."""
    lines = {name: len((REPO / name).read_text().splitlines())
             for name in ("roshan/kernels/fire.py", "roshan/runs/train.py")}
    assert lines["roshan/kernels/fire.py"] <= 800 and lines["roshan/runs/train.py"] <= 350, lines


def test_the_battery_stays_one_component():
    """The battery is one component (kernels/battery.py) that the rest asks through its interface, so few modules
    need to know there is one; and the kernels' compile-time branches stay few (each multiplies the variants)."""
    package = REPO / "roshan"
    knowing = sorted(str(p.relative_to(REPO)) for p in package.rglob("*.py")
                     if re.search(r"energy|battery", p.read_text(), re.IGNORECASE))
    assert "roshan/kernels/battery.py" in knowing and len(knowing) <= 10, knowing
    branches = sum(p.read_text().count("if ti.static(") for p in (package / "kernels").rglob("*.py"))
    assert 0 < branches <= 60, branches
