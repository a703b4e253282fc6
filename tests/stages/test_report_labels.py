"""Foreign bags labelled one by one; a warning before unlabelled ones are merged; the CLI's
--version, -o and --tool-offset."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from pipeline import __version__
from pipeline.cli import main
from tests.analysis.bagfactory import paper_like, write_bag


def _foreign(root: Path) -> Path:
    for name, scale in (("bag_a", 1e-3), ("bag_b", 3e-3)):
        ep = paper_like(name, "x", error_scale=scale)
        ep.episode_metadata = False
        write_bag(root / "recordings", ep)
    return root / "recordings"


def _run(monkeypatch: pytest.MonkeyPatch, *args: str) -> int:
    monkeypatch.setattr(sys, "argv", ["pipeline", *args])
    with pytest.raises(SystemExit) as exit_info:
        main()
    return int(exit_info.value.code or 0)


def test_two_labelled_foreign_bags_are_two_controllers(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _foreign(tmp_path)
    code = _run(
        monkeypatch, "report", "--recordings", str(rec), "-o", str(tmp_path / "out"),
        "--label", "bag_a=jtc", "--label", "bag_b.mcap=mpc", "--baseline", "jtc",
    )  # fmt: skip
    assert code == 0
    doc = json.loads((tmp_path / "out" / "metrics.json").read_text(encoding="utf-8"))
    assert {e["controller"] for e in doc["episodes"].values()} == {"jtc", "mpc"}
    assert doc["comparisons"][0]["candidate"] == "bag_b"
    assert "averaged as repeats" not in capsys.readouterr().err


def test_bags_sharing_a_controller_label_are_warned_about(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    rec = _foreign(tmp_path)
    code = _run(
        monkeypatch, "report", "--recordings", str(rec), "--out", str(tmp_path / "out"),
        "--controller", "jtc", "--baseline", "jtc",
    )  # fmt: skip
    assert code == 0
    err = capsys.readouterr().err
    assert "warning: bag_a: labelled 'jtc' by --controller like 1 other bag(s)" in err
    assert "--label BAG=CONTROLLER" in err
    text = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    assert "averaged as repeats of one controller" in text


def test_version_and_a_bad_label_or_tool_offset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    assert _run(monkeypatch, "--version") == 0
    assert capsys.readouterr().out.strip() == f"armlab-pipeline {__version__}"
    rec = _foreign(tmp_path)
    assert _run(monkeypatch, "report", "--recordings", str(rec), "--label", "bag_a") == 1
    assert "--label bag_a: expected BAG=CONTROLLER" in capsys.readouterr().err
    assert _run(monkeypatch, "report", "--recordings", str(rec), "--tool-offset", "1,2") == 1
    assert "--tool-offset: '1,2'" in capsys.readouterr().err
