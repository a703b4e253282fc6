"""The package's shape: no import cycle (lazy imports inside functions included), no
underscore-private name imported from another module, and no module above 600 lines
without a one-line reason at its top (STYLE.md #16, #19)."""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).parents[1]
PACKAGE = REPO / "pipeline"
MAX_LINES = 600
# A module above MAX_LINES says why in one of its first lines: "# long: <reason>".
LONG_MARK = "# long:"
HEAD_LINES = 3

# Modules allowed above MAX_LINES without a reason (none).
KNOWN_LONG: frozenset[str] = frozenset()

# Private names allowed to be imported across modules (none).
KNOWN_PRIVATE_IMPORTS: frozenset[tuple[str, str]] = frozenset()


def _modules() -> dict[str, Path]:
    """Module name -> file of every module in the package."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(REPO).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imported(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules that ``name`` imports anywhere in its file (functions too)."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: from the module's package, up level - 1
                package = name.split(".")
                package = package if is_package else package[:-1]
                package = package[: len(package) - (node.level - 1)]
                base = ".".join([*package, *([base] if base else [])])
            # `from a import b` loads the module a.b when b is one, else a
            targets = [
                f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base
                for alias in node.names
            ]
        else:
            continue
        for target in targets:
            # `import a.b.c` names a.b.c; keep the longest prefix that is one of ours
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (at load time or lazily)."""
    modules = _modules()
    return {name: _imported(name, path, modules) for name, path in modules.items()}


def _components(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[set[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, edges = work[-1]
            for nxt in edges:
                if nxt not in index:
                    index[nxt] = low[nxt] = len(index)
                    stack.append(nxt)
                    on_stack.add(nxt)
                    work.append((nxt, iter(sorted(graph[nxt]))))
                    break
                if nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = set()
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.add(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        out.append(component)
    return out


def _cycle(graph: dict[str, set[str]], component: set[str]) -> list[str]:
    """One cycle through a component, as the modules in import order (first repeated)."""
    start = min(component)
    # breadth-first from start's imports back to start, inside the component
    parent: dict[str, str] = {}
    frontier = [start]
    while frontier:
        nxt_frontier = []
        for node in frontier:
            for nxt in sorted(graph[node] & component):
                if nxt == start:
                    path = [node]
                    while path[-1] != start:
                        path.append(parent[path[-1]])
                    return [start, *reversed(path[:-1]), start]
                if nxt not in parent:
                    parent[nxt] = node
                    nxt_frontier.append(nxt)
        frontier = nxt_frontier
    return sorted(component)  # not reached: a component has a cycle through each member


def test_the_package_has_no_import_cycle():
    graph = import_graph()
    cycles = [" -> ".join(_cycle(graph, c)) for c in _components(graph)]
    assert not cycles, "import cycles: " + "; ".join(cycles)


def test_the_cycle_finder_names_a_lazy_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    (component,) = _components(graph)
    assert component == {"a", "b", "c"}
    assert _cycle(graph, component) == ["a", "b", "c", "a"]


def test_import_graph_sees_lazy_and_relative_imports(tmp_path):
    modules = {"pkg": tmp_path, "pkg.x": tmp_path, "pkg.y": tmp_path, "pkg.sub.z": tmp_path}
    source = tmp_path / "x.py"
    source.write_text(
        "from pkg import y\ndef f():\n    from .sub.z import thing\n    import pkg.sub.z.deeper\n"
    )
    assert _imported("pkg.x", source, modules) == {"pkg.y", "pkg.sub.z"}


def test_no_private_name_is_imported_across_modules():
    modules = _modules()
    private = []
    for name, path in modules.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if not isinstance(node, ast.ImportFrom) or node.level or node.module is None:
                continue
            for alias in node.names:
                full = f"{node.module}.{alias.name}"
                if (
                    node.module.startswith("pipeline")
                    and alias.name.startswith("_")
                    and not alias.name.endswith("__")  # a dunder (__version__) is public
                    and (name, full) not in KNOWN_PRIVATE_IMPORTS
                ):
                    private.append(f"{name} imports {full}")
    assert not private, "private names imported across modules: " + "; ".join(private)


def test_no_module_is_long_without_a_reason():
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        lines = path.read_text().splitlines()
        if len(lines) <= MAX_LINES or rel in KNOWN_LONG:
            continue
        if not any(line.startswith(LONG_MARK) for line in lines[:HEAD_LINES]):
            long.append(f"{rel} ({len(lines)} lines)")
    assert not long, (
        f"modules above {MAX_LINES} lines without a '{LONG_MARK} <reason>' line at the top: "
        + ", ".join(long)
    )
