"""`make sync` writes the generated files; each must be what the code says now."""

from __future__ import annotations

import json

import pytest

from pipeline.devtools import sync
from pipeline.devtools.deps import closure


@pytest.fixture(scope="module")
def generated() -> dict[str, str]:
    return sync.generated()


@pytest.mark.parametrize("path", sorted(sync.GENERATORS))
def test_generated_file_is_current(generated: dict[str, str], path: str) -> None:
    current = (sync.REPO / path).read_text(encoding="utf-8")
    assert current == generated[path], f"{path} is stale: run `make sync`"


def test_record_code_leaves_out_the_report_and_the_campaigns_measuring() -> None:
    record, report = sync.record_code(), sync.report_code()
    assert "stages/record.py" in record and "stages/record.py" not in report
    assert "report" in report and not any(p.startswith("report") for p in record)
    # the campaign's in-memory measuring is no record code (its partials carry their own)
    assert "stages/partials.py" not in record
    assert all(sync.module_file(stop) is not None for stop in sync.RECORD_STOPS)


def _package(tmp_path, files: dict[str, str]):
    root = tmp_path / "pipeline"
    for rel, text in {"__init__.py": "", **files}.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root


def _names(paths, root) -> set[str]:
    return {str(p.relative_to(root)) for p in paths}


def test_closure_follows_imports_inside_functions_and_import_path_strings(tmp_path) -> None:
    root = _package(
        tmp_path,
        {
            "a.py": "def f():\n    from pipeline.sub import b\nLOADER = 'pipeline.c:load'\n",
            "sub/__init__.py": "",
            "sub/b.py": "from . import d\n",
            "sub/d.py": "",
            "c.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import pipeline.e\n",
            "e.py": "",
        },
    )
    found = _names(closure(["pipeline.a"], root=root), root)
    assert found == {"__init__.py", "a.py", "sub/__init__.py", "sub/b.py", "sub/d.py", "c.py"}


def test_closure_enters_a_command_module_at_module_level_only_and_honours_stops(
    tmp_path,
) -> None:
    root = _package(
        tmp_path,
        {
            "cli.py": "import typer\nimport pipeline.x\ndef cmd():\n    import pipeline.y\n",
            "x.py": "def f():\n    import pipeline.z\n",
            "y.py": "",
            "z.py": "",
        },
    )
    assert _names(closure(["pipeline.cli"], root=root), root) == {
        "__init__.py", "cli.py", "x.py", "z.py",
    }  # fmt: skip
    assert "z.py" not in _names(closure(["pipeline.cli"], stops=["pipeline.z"], root=root), root)


def test_check_names_a_stale_file_and_the_command(tmp_path, monkeypatch, capsys) -> None:
    monkeypatch.setattr(sync, "generated", lambda: {"dvc.yaml": "something else\n"})
    assert sync.main(["--check"]) == 1
    assert "dvc.yaml is stale: run `make sync`" in capsys.readouterr().err


def test_reader_roles_wrap_to_100_columns_and_join_back_to_the_roles() -> None:
    from pipeline.devtools.sync import reader_roles_lines

    roles = ", ".join(f"role_number_{k}" for k in range(12))  # 180 characters
    lines = reader_roles_lines(roles, indent=4)
    assert len(lines) > 1
    assert all(4 + len(line) <= 100 for line in lines)
    assert "".join(json.loads(line) for line in lines) == roles
