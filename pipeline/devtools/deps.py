"""Which pipeline files a stage's command can load: the import closure, by scanning.

Every ``import`` of a pipeline module, at any depth of a file (inside functions too; never
under ``if TYPE_CHECKING:``), and every ``"pipeline.module:object"`` string (a loader or
plug-in named by its import path) is an edge; importing ``pipeline.a.b`` also runs
``pipeline/__init__.py`` and ``pipeline/a/__init__.py``. A stage's code is the closure of
its command's imports. A CLI command module (one importing Typer) is entered at module
level only: ``pipeline/cli/__init__.py`` imports every command module, whose functions
import the other commands' code.
"""

from __future__ import annotations

import ast
import functools
import re
from collections.abc import Iterable
from pathlib import Path

import pipeline

PACKAGE = Path(pipeline.__file__).resolve().parent
_IMPORT_PATH = re.compile(r"^(pipeline(?:\.\w+)+)(?::[\w.]+)?$")


def module_file(module: str, *, root: Path = PACKAGE) -> Path | None:
    """The file of pipeline module ``module`` (a package's ``__init__.py``), or None."""
    parts = module.split(".")
    if parts[0] != "pipeline":
        return None
    base = root.joinpath(*parts[1:])
    for path in (base / "__init__.py", base.with_suffix(".py")):
        if path.is_file():
            return path
    return None


def _module_name(path: Path, *, root: Path) -> str:
    parts = ["pipeline", *path.relative_to(root).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _parents(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts) + 1)]


@functools.lru_cache(maxsize=4096)
def _parse(path: Path, stamp: tuple[int, int]) -> ast.Module:
    """``path``'s syntax tree (``stamp``: its mtime and size, so an edited file is re-read)."""
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _tree(path: Path) -> ast.Module:
    st = path.stat()
    return _parse(path, (st.st_mtime_ns, st.st_size))


def _is_type_checking(node: ast.AST) -> bool:
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _nodes(body: list[ast.stmt], *, top_level_only: bool) -> list[ast.AST]:
    """The nodes that run: never an ``if TYPE_CHECKING:`` block; with ``top_level_only``,
    never a function or class body either (module level, ``if``/``try``/``with`` blocks)."""
    out: list[ast.AST] = []
    todo: list[ast.AST] = list(body)
    while todo:
        node = todo.pop()
        if isinstance(node, ast.If) and _is_type_checking(node):
            todo += node.orelse
            continue
        if top_level_only and isinstance(
            node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef | ast.Lambda
        ):
            continue
        out.append(node)
        todo += ast.iter_child_nodes(node)
    return out


def is_command_module(path: Path) -> bool:
    """A CLI command module (it imports Typer): its functions' imports are its commands'."""
    for node in _nodes(_tree(path).body, top_level_only=True):
        if isinstance(node, ast.Import) and any(a.name == "typer" for a in node.names):
            return True
        if isinstance(node, ast.ImportFrom) and node.module == "typer":
            return True
    return False


def imports_of(path: Path, *, root: Path = PACKAGE, top_level_only: bool = False) -> set[str]:
    """The pipeline modules file ``path`` imports (with their parent packages)."""
    tree = _tree(path)
    here = _module_name(path, root=root)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    found: set[str] = set()
    for node in _nodes(tree.body, top_level_only=top_level_only):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([node.module] if node.module else [])])
            else:
                base = node.module or ""
            names = [base, *(f"{base}.{a.name}" for a in node.names)]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            match = _IMPORT_PATH.match(node.value)
            names = [match.group(1)] if match else []
        for name in names:
            found.update(p for p in _parents(name) if module_file(p, root=root) is not None)
    return found


def closure(
    entries: Iterable[str], *, stops: Iterable[str] = (), root: Path = PACKAGE
) -> set[Path]:
    """The files of every pipeline module reachable from ``entries``, never entering a
    module under ``stops``; a command module (:func:`is_command_module`) contributes its
    module-level imports only."""
    stop = tuple(stops)

    def stopped(module: str) -> bool:
        return any(module == s or module.startswith(s + ".") for s in stop)

    seen: set[str] = set()
    todo = [m for e in entries for m in _parents(e)]
    while todo:
        module = todo.pop()
        if module in seen or stopped(module):
            continue
        seen.add(module)
        path = module_file(module, root=root)
        if path is not None:
            todo += sorted(imports_of(path, root=root, top_level_only=is_command_module(path)))
    return {p for m in seen if (p := module_file(m, root=root)) is not None}
