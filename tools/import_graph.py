"""The import graph of addon/mocap_autolabel: circles, imports that point up a layer, long functions.

    python tools/import_graph.py [--json] [--long-functions] [--max-lines N]

Every module is parsed with ``ast``; imports anywhere in a module count (module level and inside
functions), relative imports are resolved, and ``from .x import y`` where ``y`` is a submodule counts
as importing that submodule (otherwise as importing ``x``).

Layers, lowest first: ``core`` < the orchestrator (``core/pipeline.py``, ``core/windows.py``) < the
per-take entry (``core/process.py``) < ``blender`` < ``operators`` < ``ui`` < the package's ``__init__``.
The front ends (``cli.py``, ``batch.py``, ``farm.py``, ``html_report.py``, ``__main__.py``, and any
other top-level module) sit above core: core must not import them (their order against
blender/operators/ui is not checked).

Prints (a) every import circle (a strongly connected component of more than one module, with one
example cycle), (b) every import from a lower layer to a higher one and, with ``--long-functions``,
(c) every function in core longer than ``--max-lines`` lines (``def`` to its last line). Exit status
1 when anything is found.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path

PACKAGE = "mocap_autolabel"
PACKAGE_DIR = Path(__file__).resolve().parents[1] / "addon" / PACKAGE

#: Orchestrator modules of core: above every other core module.
ORCHESTRATOR = frozenset({f"{PACKAGE}.core.pipeline", f"{PACKAGE}.core.windows"})
#: The per-take entry of the front ends: above the orchestrator, the top of core.
ENTRY = frozenset({f"{PACKAGE}.core.process"})
#: Front ends: above core, never imported by it.
FRONT = frozenset(f"{PACKAGE}.{name}" for name in ("cli", "batch", "farm", "html_report", "__main__"))
#: Ordered layers (rank, name); FRONT is outside this order except for being above core.
RANKS = {"core": 0, "orchestrator": 1, "entry": 2, "blender": 3, "operators": 4, "ui": 5, "__init__": 6}
MAX_FUNCTION_LINES = 120


@dataclass(frozen=True)
class Edge:
    importer: str
    imported: str
    line: int


@dataclass
class Report:
    modules: int = 0
    circles: list[dict] = field(default_factory=list)
    upward: list[dict] = field(default_factory=list)
    long_functions: list[dict] = field(default_factory=list)

    @property
    def found(self) -> bool:
        return bool(self.circles or self.upward or self.long_functions)


def module_files(package_dir: Path = PACKAGE_DIR) -> dict[str, Path]:
    """Every module of the package: dotted name -> file (a package is its ``__init__.py``)."""
    modules = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = list(path.relative_to(package_dir).with_suffix("").parts)
        if "__pycache__" in parts:
            continue
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join([PACKAGE, *parts])] = path
    return modules


def _longest_module(name: str, modules: dict[str, Path]) -> str | None:
    """``name`` or its longest prefix that is a module of the package."""
    parts = name.split(".")
    while parts:
        candidate = ".".join(parts)
        if candidate in modules:
            return candidate
        parts.pop()
    return None


def _targets(node: ast.Import | ast.ImportFrom, module: str, is_package: bool,
             modules: dict[str, Path]) -> list[str]:
    """The package's modules that one import statement imports."""
    if isinstance(node, ast.Import):
        found = [_longest_module(alias.name, modules) for alias in node.names]
        return [name for name in found if name]
    if node.level:
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        source = ".".join(base + ([node.module] if node.module else []))
    else:
        source = node.module or ""
    if source.split(".")[0] != PACKAGE:
        return []
    targets = []
    for alias in node.names:
        submodule = f"{source}.{alias.name}"
        target = submodule if submodule in modules else _longest_module(source, modules)
        if target and target not in targets:
            targets.append(target)
    return targets


def import_edges(modules: dict[str, Path]) -> list[Edge]:
    """Every import of one package module by another, wherever the import statement is."""
    edges = []
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_package = path.name == "__init__.py"
        for node in ast.walk(tree):
            if isinstance(node, ast.Import | ast.ImportFrom):
                for target in _targets(node, module, is_package, modules):
                    if target != module:
                        edges.append(Edge(module, target, node.lineno))
    return sorted(set(edges), key=lambda e: (e.importer, e.line, e.imported))


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components (iterative), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                components.append(sorted(component))
    return components


def _example_cycle(component: list[str], graph: dict[str, set[str]]) -> list[str]:
    """A shortest cycle through the component's first module, staying inside the component (BFS)."""
    members = set(component)
    start = component[0]
    parents: dict[str, str] = {}
    queue = [start]
    while queue:
        node = queue.pop(0)
        for child in sorted(graph[node] & members):
            if child == start:
                path = [node]
                while path[-1] != start:
                    path.append(parents[path[-1]])
                return [start, *reversed(path[:-1]), start] if len(path) > 1 else [start, node, start]
            if child not in parents:
                parents[child] = node
                queue.append(child)
    return [start]


def circles(modules: dict[str, Path], edges: list[Edge]) -> list[dict]:
    """Every strongly connected component of more than one module, with an example cycle."""
    graph: dict[str, set[str]] = {module: set() for module in modules}
    for edge in edges:
        graph[edge.importer].add(edge.imported)
    found = []
    for component in _strongly_connected(graph):
        if len(component) > 1:
            found.append({"modules": [short(m) for m in component],
                          "cycle": [short(m) for m in _example_cycle(component, graph)]})
    return sorted(found, key=lambda c: c["modules"])


def layer(module: str) -> str:
    """The layer of a module: core, orchestrator, entry, front, blender, operators, ui or __init__."""
    if module == PACKAGE:
        return "__init__"
    if module in ORCHESTRATOR:
        return "orchestrator"
    if module in ENTRY:
        return "entry"
    if module in FRONT:
        return "front"
    top = module.split(".")[1]
    return top if top in RANKS else "front"


def _is_upward(importer: str, imported: str) -> bool:
    low, high = layer(importer), layer(imported)
    if high == "front":
        return low in ("core", "orchestrator", "entry")
    if low == "front":
        return False
    return RANKS[high] > RANKS[low]


def upward_imports(edges: list[Edge]) -> list[dict]:
    """Every import from a lower layer to a higher one."""
    return [{"importer": short(e.importer), "imported": short(e.imported), "line": e.line,
             "importer_layer": layer(e.importer), "imported_layer": layer(e.imported)}
            for e in edges if _is_upward(e.importer, e.imported)]


def long_functions(modules: dict[str, Path], max_lines: int = MAX_FUNCTION_LINES,
                   under: str = f"{PACKAGE}.core", package_dir: Path = PACKAGE_DIR) -> list[dict]:
    """Every function (methods and nested ones too) of the modules under ``under`` longer than
    ``max_lines`` lines, counted from its ``def`` to its last line."""
    found = []
    for module, path in modules.items():
        if module != under and not module.startswith(under + "."):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = node.end_lineno - node.lineno + 1
                if lines > max_lines:
                    found.append({"file": path.relative_to(package_dir).as_posix(), "function": node.name,
                                  "line": node.lineno, "lines": lines})
    return sorted(found, key=lambda f: (f["file"], f["line"]))


def short(module: str) -> str:
    """A module's name without the package prefix (the package itself is ``__init__``)."""
    return "__init__" if module == PACKAGE else module[len(PACKAGE) + 1:]


def check(package_dir: Path = PACKAGE_DIR, with_long_functions: bool = False,
          max_lines: int = MAX_FUNCTION_LINES) -> Report:
    """The whole check: circles, upward imports and (optionally) long functions in core."""
    modules = module_files(package_dir)
    edges = import_edges(modules)
    report = Report(modules=len(modules), circles=circles(modules, edges), upward=upward_imports(edges))
    if with_long_functions:
        report.long_functions = long_functions(modules, max_lines, package_dir=package_dir)
    return report


def _print_text(report: Report, with_long_functions: bool, max_lines: int) -> None:
    print(f"{report.modules} modules")
    print(f"import circles: {len(report.circles)}")
    for circle in report.circles:
        print(f"  {', '.join(circle['modules'])}")
        print(f"    e.g. {' -> '.join(circle['cycle'])}")
    print(f"upward imports: {len(report.upward)}")
    for up in report.upward:
        print(f"  {up['importer']}:{up['line']} ({up['importer_layer']}) imports "
              f"{up['imported']} ({up['imported_layer']})")
    if with_long_functions:
        print(f"functions in core over {max_lines} lines: {len(report.long_functions)}")
        for fn in report.long_functions:
            print(f"  {fn['file']}:{fn['line']} {fn['function']} ({fn['lines']} lines)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", action="store_true", help="machine output (one JSON object)")
    parser.add_argument("--long-functions", action="store_true",
                        help="also list the functions in core longer than --max-lines")
    parser.add_argument("--max-lines", type=int, default=MAX_FUNCTION_LINES, help="(default %(default)s)")
    parser.add_argument("--package", type=Path, default=PACKAGE_DIR, help="the package folder (default %(default)s)")
    args = parser.parse_args(argv)
    report = check(args.package, args.long_functions, args.max_lines)
    if args.json:
        out = asdict(report)
        if not args.long_functions:
            del out["long_functions"]
        print(json.dumps(out, indent=2))
    else:
        _print_text(report, args.long_functions, args.max_lines)
    return 1 if report.found else 0


if __name__ == "__main__":
    sys.exit(main())
