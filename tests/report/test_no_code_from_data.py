"""Reading a bag never runs code: a controller label or recorded type of the form
``module:Object`` is plain text, never imported (rosbags resolves types from the bag's own
schemas, never from code)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.control.info import declared_color, stiffness_gains
from pipeline.control.registry import known_entry
from tests.analysis.bagfactory import paper_like, write_bag

ROOT = Path(__file__).resolve().parents[2]


def test_a_module_object_name_read_from_data_resolves_to_nothing_and_imports_nothing() -> None:
    before = "this" in sys.modules
    assert known_entry("this:s") is None and known_entry("pid") is not None
    assert stiffness_gains("this:s") is None and declared_color("this:s") is None
    assert ("this" in sys.modules) == before


@pytest.mark.slow
@pytest.mark.parametrize("own", [False, True], ids=["foreign-folder-name", "recorded-type"])
def test_a_bag_labelled_this_colon_s_reports_without_importing_this(
    tmp_path: Path, own: bool
) -> None:
    for name, controller, scale in (("this:s", "this:s", 1e-3), ("pid-0", "pid", 2e-3)):
        ep = paper_like(name, controller, error_scale=scale)
        ep.episode_metadata = own
        write_bag(tmp_path / "recordings", ep)
    baseline = "pid" if own else "pid-0"
    script = (
        "import sys\n"
        "from pathlib import Path\n"
        "from pipeline.stages.report import run_report\n"
        f"run_report(recordings_dir=Path({str(tmp_path / 'recordings')!r}),"
        f" out_dir=Path({str(tmp_path / 'out')!r}), baseline={baseline!r})\n"
        "print('IMPORTED' if 'this' in sys.modules else 'CLEAN')\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=300,
        check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "CLEAN"
    assert "Beautiful is better than ugly" not in done.stdout + done.stderr
    assert "this:s" in (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
