"""One statistical method per question: a paired interval for the size, a test of the sign
only with enough pairs, Holm-corrected per table with the count stated, ratios past -100 %."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import polars as pl
import pytest

from pipeline.analysis import catalog
from pipeline.analysis.campaign_tables import TOO_FEW, holm, smallest_p, win_loss
from pipeline.report.campaign_section import campaign_section
from tests.report.campaignfactory import table_frame, table_row

JOINTS = ("j1", "j2", "j3")
CONDITIONS = ("a", "b")


def _table(pairs: int, *, ratio: float = 1.3) -> pl.DataFrame:
    rng = np.random.default_rng(pairs)
    rows = []
    for cond in CONDITIONS:
        for seed in range(pairs):
            for controller, scale in (("pid", 1.0), ("ctc", ratio)):
                for joint in JOINTS:
                    value = 1e-3 * scale * (1 + 0.05 * rng.standard_normal())
                    rows.append(table_row(cond, controller, seed, joint, value))
    return table_frame(rows)


def _section(tmp_path: Path, table: pl.DataFrame) -> str:
    path = tmp_path / "c.parquet"
    table.write_parquet(path)
    (tmp_path / "campaigns").mkdir(exist_ok=True)
    sec = campaign_section(
        path, out_dir=tmp_path, rel_table="campaigns/c.parquet", name="c", stem="c",
        baseline="pid", sample={}, draw=False,
    )  # fmt: skip
    return "\n".join(sec.lines)


def test_five_pairs_give_an_interval_and_no_p_value(tmp_path: Path) -> None:
    assert smallest_p("Wilcoxon signed-rank (paired by seed)", 5) > 0.05
    table = _table(5)
    wl = win_loss(table, baseline="pid", metrics=catalog.JOINT_COMPARED)
    assert set(wl.get_column("test").to_list()) == {TOO_FEW}
    assert wl.get_column("p_value").null_count() == wl.height
    assert wl.get_column("effect_ci95_half_width").null_count() == 0
    text = _section(tmp_path, table)
    assert not re.search(r"p = |p=", text)
    assert "too few pairs for a test" in text
    assert re.search(r"\| -\d+ ± \d+ % \(n = 5; too few pairs for a test\)", text)


def test_twenty_pairs_are_holm_corrected_per_table_and_the_count_stated(tmp_path: Path) -> None:
    table = _table(20)
    wl = win_loss(table, baseline="pid", metrics=catalog.JOINT_COMPARED)
    family = wl.filter((pl.col("metric") == "max_abs_error") & (pl.col("candidate") == "ctc"))
    per_table = len(JOINTS) * len(CONDITIONS)
    assert family.get_column("tests").to_list() == [per_table] * per_table
    raw, adjusted = family.get_column("p_value").to_list(), family.get_column("p_holm").to_list()
    assert adjusted == holm(raw)
    assert all(a >= r for a, r in zip(adjusted, raw, strict=True))
    assert min(adjusted) == pytest.approx(min(1.0, per_table * min(raw)))
    assert set(family.get_column("verdict").to_list()) == {"loses"}
    text = _section(tmp_path, table)
    assert f"({per_table} test(s) per table)" in text
    assert re.search(r"\*\*loses\*\* -\d+ ± \d+ % \(Holm p = [\d.e-]+, n = 20\)", text)


def test_a_candidate_many_times_the_baseline_reads_as_a_ratio(tmp_path: Path) -> None:
    text = _section(tmp_path, _table(5, ratio=33.7))
    assert not re.search(r"-\d{3,} %", text)
    assert "× the baseline's" in text
