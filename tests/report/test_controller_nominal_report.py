"""The report's setup names each controller's nominal model, as its bags record it, and
a comparison of controllers that share no seed says so instead of pairing them."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.stages.report import run_report
from tests.analysis.bagfactory import default_settings, paper_like, write_bag

SHA = "ab" * 32


def _report(root: Path, *, seeds: dict[str, list[int]]) -> str:
    for controller, own in seeds.items():
        for seed in own:
            scale = 1.5e-3 if controller == "ctc_id" else 1e-3
            ep = paper_like(f"{controller}-{seed}", controller, seed=seed, error_scale=scale)
            settings = default_settings(ep)
            settings["controller"]["type"] = "ctc"
            if controller == "ctc_id":
                settings["controller"]["nominal"] = {"file": "models/ur5.yaml", "sha256": SHA}
            ep.settings = settings
            write_bag(root / "recordings", ep)
    run_report(recordings_dir=root / "recordings", out_dir=root / "reports", baseline="ctc")
    return (root / "reports" / "report.md").read_text(encoding="utf-8")


@pytest.mark.slow
def test_the_setup_names_each_nominal_and_unshared_seeds_are_not_paired(tmp_path: Path) -> None:
    """ctc (CAD) and ctc_id (its own model) on seeds 0, 1; ctc_late on seeds 2, 3 only."""
    text = _report(tmp_path, seeds={"ctc": [0, 1], "ctc_id": [0, 1], "ctc_late": [2, 3]})
    assert "Nominal model per controller" in text
    assert "- ctc: the robot description's (CAD) values." in text
    assert "- ctc_late: the robot description's (CAD) values." in text
    assert f"- ctc_id: `models/ur5.yaml` (SHA-256 {SHA[:16]}…)." in text
    assert "**ctc_id vs ctc** in `paper` (2 seed pairs" in text
    late = next(x for x in text.splitlines() if x.startswith("- **ctc_late vs ctc**"))
    assert "runs do not share seeds" in late and "seed pair" not in late
