"""headline.json, the declared DVC metric: small, scalars in nested dicts, both spaces."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from pipeline.analysis.headline import HEADLINE_MAX_SCALARS
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


# What DVC prints (measured in a clone after `dvc exp run`; docs/report.md "Headline numbers
# for DVC"): `dvc metrics diff` one header line, then a line per changed scalar (`--all`:
# per scalar); `dvc exp show --only-changed --csv` the Experiment, rev, typ and Created
# columns (the table shows two of them), then one per changed param, changed dependency
# (`recordings`, the report's) and changed metric.
METRICS_DIFF_MAX_LINES = 60
EXP_SHOW_MAX_COLUMNS = 40
EXP_SHOW_FIXED_COLUMNS = 4
CHANGED_DEPS = 1
# The README's experiments: CTC's kp and kd; the gain sweep's PID omega_n_rad_s with CTC's
# kp and kd (the baseline changes, so every reduction does).
CTC_CHANGE_PARAMS = 2
SWEEP_PARAMS = 3


@pytest.fixture(scope="module")
def headline(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """headline.json of a report on recordings shaped like the default experiment's."""
    root = tmp_path_factory.mktemp("headline")
    for group, (controllers, seeds) in _default_experiment_shape().items():
        for controller in controllers:
            for seed in range(seeds):
                ep = paper_like(
                    f"{group}-{controller}-{seed}", controller, scenario=group, seed=seed,
                    duration_s=0.6, motion_end_s=0.4,
                    error_scale=1e-3 * (1 + 0.1 * seed) * (1.5 if controller != "pid" else 1),
                )  # fmt: skip
                write_bag(root / "recordings", ep)
    # jobs=1: a report worker pool's start-up repays nothing on the suite's busy cores, and the
    # outputs do not depend on jobs (tests/stages/test_report_jobs.py)
    run_report(recordings_dir=root / "recordings", out_dir=root / "reports", jobs=1)
    doc: dict[str, Any] = json.loads((root / "reports" / "headline.json").read_text("utf-8"))
    return doc


def _keys(x: Any, prefix: str = "") -> list[str]:
    if isinstance(x, dict):
        return [k for key, value in x.items() for k in _keys(value, f"{prefix}.{key}")]
    return [prefix.lstrip(".")]


def test_headline_json_of_the_default_experiments_shape_stays_small(
    headline: dict[str, Any],
) -> None:
    leaves = _leaves(headline)
    assert all(v is None or isinstance(v, int | float) for v in leaves)
    assert 0 < len(leaves) <= HEADLINE_MAX_SCALARS
    # `dvc metrics diff --all` prints every scalar: it fits too
    assert 1 + len(leaves) <= METRICS_DIFF_MAX_LINES
    node = headline["paper-realistic"]["ctc_vs_pid"]
    assert set(node) == {
        "n", "shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
        "wrist_2_joint", "wrist_3_joint", "tcp_position", "tcp_orientation",
    }  # fmt: skip
    assert node["n"] == 10
    for row in ("shoulder_pan_joint", "wrist_3_joint", "tcp_position", "tcp_orientation"):
        assert set(node[row]) == {"max_error_reduction_pct", "ci95_half_width"}, row
    assert node["tcp_position"]["max_error_reduction_pct"] < 0
    assert set(headline["paper-realistic"]) == {"ctc_vs_pid", "ctc_pid_vs_pid"}
    # the ideal plant's single pair has no interval: metrics.json's `headline` keeps it
    assert "paper" not in headline


def test_a_gain_change_fits_dvc_metrics_diff_and_exp_show(headline: dict[str, Any]) -> None:
    """The README's two experiments, counted as `dvc exp show --only-changed --csv` does. A
    CTC gain change (`-S controllers.ctc.gains.kp=... -S ...kd=...`) changes the
    comparisons CTC is in; the gain sweep (PID's `omega_n_rad_s` with CTC's kp and kd)
    changes the baseline, so every comparison, half widths included."""
    keys = [k for k in _keys(headline) if not k.endswith(".n")]  # pairs do not change
    ctc = [k for k in keys if "ctc_vs_" in k or "_vs_ctc." in k]
    assert 1 + len(keys) <= METRICS_DIFF_MAX_LINES  # either experiment's metrics diff
    fixed = EXP_SHOW_FIXED_COLUMNS + CHANGED_DEPS
    assert fixed + CTC_CHANGE_PARAMS + len(ctc) <= EXP_SHOW_MAX_COLUMNS
    assert fixed + SWEEP_PARAMS + len(keys) <= EXP_SHOW_MAX_COLUMNS
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    assert "dvc exp run --run-all && dvc exp show --only-changed\n" in readme  # no --drop


def test_only_single_pairs_still_make_a_headline(tmp_path: Path) -> None:
    """Without repeated runs every comparison is a single pair: headline.json holds them,
    with no half widths (rather than being empty)."""
    for controller in ("pid", "ctc"):
        scale = 1e-3 if controller == "pid" else 5e-4
        ep = paper_like(
            f"paper-{controller}", controller, duration_s=0.6, motion_end_s=0.4, error_scale=scale
        )
        write_bag(tmp_path / "recordings", ep)
    run_report(recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports")
    doc = json.loads((tmp_path / "reports" / "headline.json").read_text("utf-8"))
    node = doc["paper"]["ctc_vs_pid"]
    assert node["n"] == 1
    assert set(node["tcp_position"]) == {"max_error_reduction_pct"}
    assert node["shoulder_pan_joint"]["max_error_reduction_pct"] > 0


def test_dvc_declares_the_headline_as_its_metric_and_metrics_json_as_an_output() -> None:
    stage = yaml.safe_load((REPO / "dvc.yaml").read_text(encoding="utf-8"))["stages"]["report"]
    metrics = [next(iter(m)) if isinstance(m, dict) else m for m in stage["metrics"]]
    outs = [next(iter(o)) if isinstance(o, dict) else o for o in stage["outs"]]
    assert metrics == ["reports/headline.json"]
    assert "reports/metrics.json" in outs
