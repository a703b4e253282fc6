"""Campaigns in the report: the Parquet table equals the recordings' metrics, the summary
(win/loss, distributions, CI bands), flat headline keys for DVC, bounded output sizes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pytest

from pipeline.analysis import catalog
from pipeline.report.colors import FIXED, hex_color
from pipeline.stages.report import ReportResult, run_report
from tests.analysis.bagfactory import paper_like, write_bag
from tests.report.campaignfactory import PAYLOADS_KG, campaign_episodes, write_campaign

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> tuple[ReportResult, list[Any]]:
    root = tmp_path_factory.mktemp("campaign")
    # 10 seed pairs: the signed-rank test's smallest p (2 / 2^10) survives Holm over 18 tests
    episodes = campaign_episodes(seeds=10)
    write_campaign(root / "recordings", episodes)
    # a hand-listed pair beside the campaign
    write_bag(root / "recordings", paper_like("paper-pid", "pid", duration_s=0.3, motion_end_s=0.2))
    write_bag(
        root / "recordings",
        paper_like("paper-ctc", "ctc", duration_s=0.3, motion_end_s=0.2, error_scale=5e-4),
    )
    # jobs=1: a report worker pool's start-up repays nothing on the suite's busy cores, and the
    # outputs do not depend on jobs (tests/stages/test_report_jobs.py)
    result = run_report(recordings_dir=root / "recordings", out_dir=root / "reports", jobs=1)
    return result, episodes


def test_campaign_table_has_the_interface_columns(campaign: tuple[ReportResult, Any]) -> None:
    result, episodes = campaign
    table = pl.read_parquet(result.out_dir / "campaigns" / "sweep.parquet")
    assert table.columns[:5] == ["episode", "campaign", "condition", "controller", "seed"]
    assert {"swept.controller", "swept.seed", "swept.plant.payload_kg", "status", "joint"} <= set(
        table.columns
    )
    assert set(catalog.METRIC_COLUMNS) <= set(table.columns)
    assert table.height == len(episodes) * 7  # six joints and the TCP
    assert table.schema["swept.plant.payload_kg"] == pl.Float64
    assert sorted(table["swept.plant.payload_kg"].unique().to_list()) == list(PAYLOADS_KG)
    # hand-listed episodes are in no campaign table
    assert "paper-pid" not in table["episode"].to_list()
    index = pl.read_csv(result.out_dir / "campaigns" / "index.csv")
    assert index.rows() == [("sweep", len(episodes), len(PAYLOADS_KG), "campaigns/sweep.parquet")]


def test_campaign_table_equals_metrics_json_and_the_written_arrays(
    campaign: tuple[ReportResult, Any],
) -> None:
    result, episodes = campaign
    table = pl.read_parquet(result.out_dir / "campaigns" / "sweep.parquet")
    doc = json.loads((result.out_dir / "metrics.json").read_text(encoding="utf-8"))
    for row in table.iter_rows(named=True):
        joint = doc["episodes"][row["episode"]]["joints"][row["joint"]]
        for m in catalog.METRICS:
            if not m.applies_to(row["joint"]):
                assert row[m.name] is None and m.name not in joint
            elif row[m.name] is None:
                assert joint[m.name] is None
            else:
                assert joint[m.name] == pytest.approx(row[m.name], rel=1e-8, abs=1e-12), m.name
    # independently of the metric code: max |q_ref - q| of the arrays written into the bags
    for ep in episodes[:4]:
        rows = table.filter((pl.col("episode") == ep.episode) & (pl.col("joint") != "tcp"))
        expected = np.abs(ep.q_ref - ep.q).max(axis=0)
        np.testing.assert_allclose(rows["max_abs_error"].to_numpy(), expected, rtol=1e-9)


def test_win_loss_finds_where_ctc_stops_winning(campaign: tuple[ReportResult, Any]) -> None:
    result, _ = campaign
    wl = pl.read_csv(result.out_dir / "campaigns" / "sweep_win_loss.csv")
    j1 = wl.filter(
        (pl.col("metric") == "max_abs_error") & (pl.col("joint") == "shoulder_pan_joint")
    )
    verdicts = dict(zip(j1["condition"].to_list(), j1["verdict"].to_list(), strict=True))
    # CTC's error is 4x smaller at 0 kg and about 1.7x larger at 1 kg, same seeds: 10 pairs
    assert verdicts["plant.payload_kg=0"] == "wins"
    assert verdicts["plant.payload_kg=1"] == "loses"
    assert set(j1["test"].to_list()) == {"Wilcoxon signed-rank (paired by seed)"}
    assert j1["n"].to_list() == [10, 10, 10]
    assert set(j1["tests"].to_list()) == {18}  # 6 joints x 3 conditions, Holm-corrected
    text = (result.out_dir / "report.md").read_text(encoding="utf-8")
    assert "## Campaign `sweep`" in text
    assert "#### Max |error|: `ctc` vs `pid`" in text
    for name in ("distribution", "ecdf", "vs_plant.payload_kg"):
        assert (result.out_dir / "figures" / f"sweep_max_abs_error_{name}.png").stat().st_size


def test_headline_keys_are_flat_scalars_reachable_through_dicts(
    campaign: tuple[ReportResult, Any],
) -> None:
    result, _ = campaign
    doc = json.loads((result.out_dir / "metrics.json").read_text(encoding="utf-8"))
    node = doc["headline"]["sweep/plant.payload_kg=1"]["ctc_vs_pid"]["shoulder_pan_joint"]
    cell = node["max_abs_error"]
    assert set(cell) == {"reduction_pct", "ci95_low", "ci95_high", "n"}
    assert cell["n"] == 10
    assert cell["ci95_low"] < cell["reduction_pct"] < cell["ci95_high"] < 0
    agg = doc["aggregates"]["sweep/plant.payload_kg=1"]["controllers"]["ctc"]
    assert agg["shoulder_pan_joint"]["max_abs_error"]["n"] == 10
    single = doc["headline"]["paper"]["ctc_vs_pid"]["shoulder_pan_joint"]["max_abs_error"]
    assert single["n"] == 1 and single["ci95_low"] is None
    assert single["reduction_pct"] == pytest.approx(50.0, rel=1e-3)

    def leaves(x: Any) -> list[Any]:
        if isinstance(x, dict):
            return [v for value in x.values() for v in leaves(value)]
        assert not isinstance(x, list), "DVC ignores lists"
        return [x]

    assert all(v is None or isinstance(v, int | float) for v in leaves(doc["headline"]))


def test_plot_csvs_carry_the_controller_and_only_the_sample(
    campaign: tuple[ReportResult, Any],
) -> None:
    result, episodes = campaign
    frame = pl.read_csv(result.out_dir / "plots" / "errors.csv")
    assert frame.columns == ["time_s", "controller", "episode", "joint", "value"]
    shown = set(frame["episode"].unique().to_list())
    # median and worst per controller and condition, plus the hand-listed pair
    assert len(shown) == 2 * 2 * len(PAYLOADS_KG) + 2 < len(episodes)


def test_dvc_template_colours_controllers_as_the_figures_do() -> None:
    template = json.loads((REPO / ".dvc" / "plots" / "controller_joint.json").read_text())
    enc = template["spec"]["encoding"]
    assert enc["color"]["field"] == "controller"
    scale = enc["color"]["scale"]
    assert dict(zip(scale["domain"], scale["range"], strict=True)) == {
        k: hex_color(v) for k, v in FIXED.items()
    }
    assert enc["strokeDash"]["field"] == "rev"
    assert {d["field"] for d in enc["detail"]} == {"episode", "rev"}
