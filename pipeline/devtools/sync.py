"""``make sync``: write the files that are generated from the code, so nothing is kept
equal by hand.

- dvc.yaml's record and report deps, and ``RECORD_CODE`` (pipeline/stages/provenance.py):
  the import closure of each command (:mod:`pipeline.devtools.deps`);
- ``BUILTIN_INFO`` in pipeline/control/info.py: the built-in controllers' declared facts,
  read from their classes (the report reads this table and never imports a controller);
- ``.dvc/plots/controller_joint.json``: the built-in controllers' colours;
- docs/report.md's metric definitions: the metric catalog's;
- the reader roles in ``pipeline report --topic``'s help (pipeline/cli/report_cmd.py):
  :data:`pipeline.log.topics.ROLES`.

``python -m pipeline.devtools.sync`` writes what is stale; ``--check`` only lists it (exit 1).
The tests run :func:`generated` in memory and compare.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

from pipeline.devtools.deps import PACKAGE, closure, imports_of, module_file

REPO = PACKAGE.parent

# The commands' modules: a stage's code is what their command functions import.
RECORD_COMMAND = "pipeline.cli.record_cmd"
REPORT_COMMAND = "pipeline.cli.report_cmd"
# The record stage does not depend on the code that measures a campaign's episodes as
# they are recorded (their partials carry that code's own commit: stages/partials.py
# MEASURE_CODE, and are re-made when it changes): the closure does not enter it.
RECORD_STOPS = (
    "pipeline.stages.report",
    "pipeline.stages.partials",
    "pipeline.log.whole",
    "pipeline.report",
)
_NOT_DATA = {"py.typed"}  # a marker for type checkers, never read by a command


def _begin(name: str) -> str:
    return f"begin generated: {name} (make sync)"


def _end(name: str) -> str:
    return f"end generated: {name}"


def stage_code(command: str, *, stops: tuple[str, ...] = ()) -> list[str]:
    """The paths (relative to pipeline/) of the code a command's stage depends on: its
    modules, the data files of their packages, a folder when all of it is."""
    path = module_file(command)
    if path is None:
        raise SystemExit(f"error: {command}: no such module (a command module was renamed?)")
    files = closure(["pipeline.__main__", "pipeline.cli", *imports_of(path)], stops=stops)
    for init in [f for f in files if f.name == "__init__.py"]:
        files |= {
            f for f in init.parent.iterdir()
            if f.is_file() and f.suffix not in (".py", ".pyc") and f.name not in _NOT_DATA
        }  # fmt: skip
    every = {f for f in PACKAGE.rglob("*") if f.is_file() and "__pycache__" not in f.parts} - {
        PACKAGE / n for n in _NOT_DATA
    }
    out: list[str] = []

    def walk(folder: Path) -> None:
        for child in sorted(folder.iterdir()):
            if child.name == "__pycache__":
                continue
            if child.is_dir():
                inside = {f for f in every if child in f.parents}
                if inside and inside <= files:
                    out.append(str(child.relative_to(PACKAGE)))
                elif inside & files:
                    walk(child)
            elif child in files:
                out.append(str(child.relative_to(PACKAGE)))

    walk(PACKAGE)
    return out


def record_code() -> list[str]:
    """The record stage's code (``RECORD_CODE``; dvc.yaml's record and campaign deps)."""
    for stop in RECORD_STOPS:
        if module_file(stop) is None:  # moved or gone: the closure may now enter its code
            sys.stderr.write(f"warning: RECORD_STOPS names {stop}, no module: update sync.py\n")
    return stage_code(RECORD_COMMAND, stops=RECORD_STOPS)


def report_code() -> list[str]:
    """The report stage's code (dvc.yaml's report deps)."""
    return stage_code(REPORT_COMMAND)


def _replace_block(text: str, name: str, lines: list[str], *, where: str) -> str:
    """``text`` with the lines between the ``begin``/``end`` comments of ``name`` replaced
    by ``lines`` (indented as the ``begin`` line)."""
    rows = text.splitlines(keepends=True)
    begin = [k for k, r in enumerate(rows) if r.rstrip().endswith(_begin(name))]
    end = [k for k, r in enumerate(rows) if r.rstrip().endswith(_end(name))]
    if len(begin) != 1 or len(end) != 1 or end[0] < begin[0]:
        raise SystemExit(f"error: {where}: expected one '{_begin(name)}' ... '{_end(name)}' block")
    indent = rows[begin[0]][: len(rows[begin[0]]) - len(rows[begin[0]].lstrip())]
    body = [f"{indent}{line}\n" if line else "\n" for line in lines]
    return "".join([*rows[: begin[0] + 1], *body, *rows[end[0] :]])


def dvc_yaml() -> str:
    path = REPO / "dvc.yaml"
    text = path.read_text(encoding="utf-8")
    text = _replace_block(
        text, "record code", [f"- pipeline/{p}" for p in record_code()], where=str(path)
    )
    return _replace_block(
        text, "report code", [f"- pipeline/{p}" for p in report_code()], where=str(path)
    )


def provenance_py() -> str:
    path = PACKAGE / "stages" / "provenance.py"
    lines = [f'"{p}",' for p in record_code()]
    return _replace_block(path.read_text(encoding="utf-8"), "record code", lines, where=str(path))


def _py_str(key: str, s: str, indent: int) -> str:
    """``key=<literal of s>``, the literal split to fit 100 columns at ``indent``."""
    one = f"{key}={json.dumps(s, ensure_ascii=False)},"
    if indent + len(one) <= 100:
        return one
    pad = " " * (indent + 4)
    chunks = textwrap.wrap(s, width=100 - len(pad) - 2, drop_whitespace=False)
    inner = "\n".join(f"{pad}{json.dumps(c, ensure_ascii=False)}" for c in chunks)
    return f"{key}=(\n{inner}\n{' ' * indent}),"


def info_py() -> str:
    """pipeline/control/info.py with the built-in controllers' records (read from their
    classes by the registry) in its generated block."""
    from pipeline.control.info import info_of
    from pipeline.control.registry import CONTROLLERS

    lines: list[str] = []
    for name, entry in CONTROLLERS.items():
        i = info_of(name, entry)
        if i is None:
            raise SystemExit(f"error: built-in controller {name}: its class declares no GAINS")
        lines += [
            "ControllerInfo(",
            f"    {_py_str('name', i.name, 8)}",
            f"    color={i.color!r},",
            f"    {_py_str('steady_offset', i.steady_offset, 8)}",
            f"    uses_nominal_model={i.uses_nominal_model!r},",
            f"    stiffness_gains={i.stiffness_gains!r},",
            f"    {_py_str('summary', i.summary, 8)}",
            "),",
        ]
    lines = [row for line in lines for row in line.split("\n")]
    path = PACKAGE / "control" / "info.py"
    text = path.read_text(encoding="utf-8")
    return _replace_block(text, "built-in controllers", lines, where=str(path))


def plot_template_json() -> str:
    from pipeline.control.registry import CONTROLLERS

    path = REPO / ".dvc" / "plots" / "controller_joint.json"
    template = json.loads(path.read_text(encoding="utf-8"))
    colored = [(n, e.color) for n, e in CONTROLLERS.items() if e.color is not None]
    template["spec"]["encoding"]["color"]["scale"] = {
        "domain": [n for n, _ in colored],
        "range": ["#{:02x}{:02x}{:02x}".format(*c) for _, c in colored],
    }
    return json.dumps(template, indent=2, ensure_ascii=False) + "\n"


def metric_definitions() -> list[str]:
    """One bullet per metric with a definition, its companions (no definition of their
    own) named with it: ``- `name` [unit], `source` — definition.``"""
    from pipeline.analysis.catalog import METRICS, Metric

    groups: list[list[Metric]] = []
    for m in METRICS:
        if m.definition or not groups:
            groups.append([m])
        else:
            groups[-1].append(m)
    out = []
    for group in groups:
        first = group[0]
        names: list[str] = []
        for k, m in enumerate(group):
            nxt = group[k + 1] if k + 1 < len(group) else None
            unit = "" if nxt is not None and nxt.unit == m.unit else f" [{m.unit}]"
            names.append(f"`{m.name}`{unit}")
        out.append(f"- {', '.join(names)}, `{first.source}` — {first.definition}.")
    return out


def report_md() -> str:
    path = REPO / "docs" / "report.md"
    text = path.read_text(encoding="utf-8")
    rows = text.splitlines(keepends=True)
    begin = f"<!-- {_begin('metric definitions')} -->"
    end = f"<!-- {_end('metric definitions')} -->"
    k0 = [k for k, r in enumerate(rows) if r.strip() == begin]
    k1 = [k for k, r in enumerate(rows) if r.strip() == end]
    if len(k0) != 1 or len(k1) != 1 or k1[0] < k0[0]:
        raise SystemExit(f"error: {path}: expected one '{begin}' ... '{end}' block")
    body = [f"{line}\n" for line in metric_definitions()]
    return "".join([*rows[: k0[0] + 1], *body, *rows[k1[0] :]])


def cli_report_py() -> str:
    """pipeline/cli/report_cmd.py with the reader roles (``--topic`` help) in its block."""
    from pipeline.log.topics import ROLES

    path = PACKAGE / "cli" / "report_cmd.py"
    text = path.read_text(encoding="utf-8")
    return _replace_block(
        text, "reader roles", reader_roles_lines(", ".join(ROLES)), where=str(path)
    )


def reader_roles_lines(roles: str, *, indent: int = 4) -> list[str]:
    """``roles`` as adjacent string literals, each line within 100 columns at ``indent``
    (a new role must not make the generated file fail the line-length lint)."""
    chunks = textwrap.wrap(roles, width=100 - indent - 2, drop_whitespace=False)
    return [json.dumps(c) for c in chunks]


GENERATORS: dict[str, Callable[[], str]] = {
    "pipeline/control/info.py": info_py,
    "pipeline/stages/provenance.py": provenance_py,
    "dvc.yaml": dvc_yaml,
    ".dvc/plots/controller_joint.json": plot_template_json,
    "docs/report.md": report_md,
    "pipeline/cli/report_cmd.py": cli_report_py,
}
"""Each generated file (relative to the repository), and what makes its text."""


def _ruff_format(path: str, text: str) -> str:
    """A generated Python file as ``ruff format`` leaves it (the repository's style)."""
    ruff = Path(sys.executable).parent / "ruff"
    done = subprocess.run(
        [str(ruff) if ruff.exists() else "ruff", "format", "--stdin-filename", path, "-"],
        input=text, capture_output=True, text=True, cwd=REPO, check=True,
    )  # fmt: skip
    return done.stdout


def generated() -> dict[str, str]:
    """The text each generated file should have."""
    out: dict[str, str] = {}
    for path, make in GENERATORS.items():
        text = make()
        out[path] = _ruff_format(path, text) if path.endswith(".py") else text
    return out


def stale() -> list[str]:
    """The generated files whose text is not what :func:`generated` makes."""
    return [
        p for p, text in generated().items()
        if not (REPO / p).is_file() or (REPO / p).read_text(encoding="utf-8") != text
    ]  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if args not in ([], ["--check"]):
        sys.stderr.write("usage: python -m pipeline.devtools.sync [--check]\n")
        return 2
    texts = generated()
    changed = [
        p for p, t in texts.items()
        if not (REPO / p).is_file() or (REPO / p).read_text(encoding="utf-8") != t
    ]  # fmt: skip
    if args == ["--check"]:
        for p in changed:
            sys.stderr.write(f"error: {p} is stale: run `make sync`\n")
        return 1 if changed else 0
    for p in changed:
        target = REPO / p
        tmp = target.with_name(target.name + ".sync-tmp")
        tmp.write_text(texts[p], encoding="utf-8")
        tmp.replace(target)
        print(f"wrote {p}")
    if not changed:
        print("all generated files are current")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
