"""The campaign report names the verdicts that change within the swept range of an
assumption (issue 19): per swept axis, the other axes held."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl

from pipeline.analysis.campaign_tables import condition_values, verdict_flips, win_loss
from pipeline.report.campaign_section import campaign_section
from tests.report.campaignfactory import table_frame, table_row

JOINTS = ("j1", "j2")


def _table(ratios: dict[tuple[str, str], float], *, pairs: int) -> pl.DataFrame:
    """ctc / pid = ratios[(condition, joint)] per seed, with a little noise."""
    rng = np.random.default_rng(0)
    rows = []
    for (cond, joint), ratio in ratios.items():
        for seed in range(pairs):
            for controller, scale in (("pid", 1.0), ("ctc", ratio)):
                value = 1e-3 * scale * (1 + 0.02 * rng.standard_normal())
                rows.append(table_row(cond, controller, seed, joint, value))
    return table_frame(rows)


# j1: CTC wins at armature_scale 4 and loses at 0.25 (with either payload); j2: always wins
RATIOS = {
    (f"armature_scale={a},payload_kg={p}", j): (0.7 if a == "4" else 1.4) if j == "j1" else 0.5
    for a in ("0.25", "4")
    for p in ("0", "1")
    for j in JOINTS
}


def test_a_verdict_that_changes_with_an_axis_is_named_and_one_that_does_not_is_not() -> None:
    wl = win_loss(_table(RATIOS, pairs=20), baseline="pid", metrics=("max_abs_error",))
    flips = verdict_flips(wl)
    assert set(flips.get_column("assumption").to_list()) == {"armature_scale"}
    assert set(flips.get_column("joint").to_list()) == {"j1"}
    assert sorted(flips.get_column("others").to_list()) == ["payload_kg=0", "payload_kg=1"]
    assert flips.get_column("answers").to_list()[0] == (
        "armature_scale=0.25: loses; armature_scale=4: wins"
    )


def test_without_a_test_the_sign_decides_and_is_marked_untested() -> None:
    wl = win_loss(_table(RATIOS, pairs=3), baseline="pid", metrics=("max_abs_error",))
    answers = verdict_flips(wl).get_column("answers").to_list()
    assert answers and all("worse (untested)" in a and "better (untested)" in a for a in answers)


def test_condition_values_parse_a_key() -> None:
    assert condition_values("armature_scale=0.25,goal=r1") == {
        "armature_scale": "0.25",
        "goal": "r1",
    }
    assert condition_values("") == {}


def test_the_campaign_section_lists_the_flips_per_assumption(tmp_path: Path) -> None:
    path = tmp_path / "c.parquet"
    _table(RATIOS, pairs=20).write_parquet(path)
    (tmp_path / "campaigns").mkdir()
    sec = campaign_section(
        path, out_dir=tmp_path, rel_table="campaigns/c.parquet", name="c", stem="c",
        baseline="pid", sample={}, draw=False,
    )  # fmt: skip
    text = "\n".join(sec.lines)
    assert "### Verdicts that flip with `armature_scale`" in text
    assert "`ctc` vs `pid`, Max |error|" in text
    assert "j1 (payload_kg=0): armature_scale=0.25: loses; armature_scale=4: wins" in text
    assert "### Verdicts that flip with `payload_kg`" in text
    # payload changes nothing: said so
    payload = text.split("### Verdicts that flip with `payload_kg`")[1]
    assert payload.lstrip().startswith("None: every verdict")
    assert "campaigns/c_flips.csv" in sec.files
