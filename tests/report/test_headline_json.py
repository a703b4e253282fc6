"""headline.json, the declared DVC metric: small, scalars in nested dicts, both spaces."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from pipeline.analysis.summary import HEADLINE_MAX_SCALARS
from pipeline.stages.report import run_report
from tests.analysis.bagfactory import paper_like, write_bag

REPO = Path(__file__).resolve().parents[2]


def _leaves(x: Any) -> list[Any]:
    if isinstance(x, dict):
        return [v for value in x.values() for v in _leaves(value)]
    assert not isinstance(x, list), "DVC ignores lists"
    return [x]


def _default_experiment_shape() -> dict[str, tuple[list[str], int]]:
    """Per group of params.yaml: its controllers and runs per controller."""
    params = yaml.safe_load((REPO / "params.yaml").read_text(encoding="utf-8"))
    groups: dict[str, tuple[list[str], int]] = {}
    for ep in params["episodes"].values():
        controllers, _ = groups.setdefault(ep["scenario"], ([], 1))
        controllers.append(ep["controller"])
    for name, campaign in params.get("campaigns", {}).items():
        groups[name] = (list(campaign["controllers"]), int(campaign.get("seeds", 1)))
    return groups


def test_headline_json_of_the_default_experiments_shape_stays_small(tmp_path: Path) -> None:
    for group, (controllers, seeds) in _default_experiment_shape().items():
        for controller in controllers:
            for seed in range(seeds):
                ep = paper_like(
                    f"{group}-{controller}-{seed}", controller, scenario=group, seed=seed,
                    duration_s=0.6, motion_end_s=0.4,
                    error_scale=1e-3 * (1 + 0.1 * seed) * (1.5 if controller != "pid" else 1),
                )  # fmt: skip
                write_bag(tmp_path / "recordings", ep)
    run_report(recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports")
    doc = json.loads((tmp_path / "reports" / "headline.json").read_text(encoding="utf-8"))
    leaves = _leaves(doc)
    assert all(v is None or isinstance(v, int | float) for v in leaves)
    assert 0 < len(leaves) <= HEADLINE_MAX_SCALARS
    node = doc["paper-realistic"]["ctc_vs_pid"]
    assert set(node) == {
        "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
        "wrist_2_joint", "wrist_3_joint", "tcp_position", "tcp_orientation",
    }  # fmt: skip
    cell = node["tcp_position"]
    assert set(cell) == {"max_error_reduction_pct", "ci95_half_width", "n"}
    assert cell["n"] == 5 and cell["max_error_reduction_pct"] < 0


def test_dvc_declares_the_headline_as_its_metric_and_metrics_json_as_an_output() -> None:
    stage = yaml.safe_load((REPO / "dvc.yaml").read_text(encoding="utf-8"))["stages"]["report"]
    metrics = [next(iter(m)) if isinstance(m, dict) else m for m in stage["metrics"]]
    outs = [next(iter(o)) if isinstance(o, dict) else o for o in stage["outs"]]
    assert metrics == ["reports/headline.json"]
    assert "reports/metrics.json" in outs
