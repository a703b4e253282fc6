"""A campaign that keeps bags for a sample: partials give the same table as full bags,
the report says which episodes have bags, a re-run by key gives the same bytes, resume."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import polars as pl
import pytest
import yaml

from pipeline.errors import ParamsError, ReportError
from pipeline.params import load_params
from pipeline.stages import report as report_stage
from pipeline.stages.campaign_run import completion_marker, plan_run, sample_without_bags
from pipeline.stages.partials import PARTIAL_DIR, read_partial
from pipeline.stages.record import record
from pipeline.stages.report import run_report

REPO = Path(__file__).parents[2]


def _params(tmp_path: Path, keep: dict[str, Any] | None, seeds: int = 2) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    for s in data["scenarios"].values():
        s.update(preroll_s=0.2, hold_s=0.2)  # short episodes: the bytes matter, not the length
    campaign: dict[str, Any] = {
        "scenario": "paper-realistic",  # seeded plant draws and sensor noise
        "controllers": ["pid", "ctc"],
        "seeds": seeds,
    }
    if keep is not None:
        campaign["keep_bags"] = keep
    data["campaigns"] = {"c": campaign}
    path = tmp_path / f"params-{'all' if keep is None else 'kept'}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _run(params: Path, out: Path, only: list[str] | None = None) -> list[Any]:
    loaded = load_params(params)
    run = plan_run(loaded, "c", out=out, only=only)
    return record(
        loaded, run.pending, out_dir=run.out_dir, force=True, commit=run.commit,
        on_event=completion_marker(run, lambda *a: None),
    )  # fmt: skip


def _bags(out: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(out)): p.read_bytes()
        for p in sorted(out.glob("c/*/*"))
        if not p.parent.name.startswith(".")
    }


@pytest.mark.slow
def test_sampled_bags_same_table_same_bytes_and_resume(tmp_path, monkeypatch):
    full, kept = tmp_path / "full", tmp_path / "kept"
    assert [o.status for o in _run(_params(tmp_path, None), full)] == ["ok"] * 4
    params = _params(tmp_path, {"every": 3})
    assert [o.status for o in _run(params, kept)] == ["ok"] * 4
    episodes = [e.name for e in plan_run(load_params(params), "c", out=kept).episodes]
    # every 3rd episode (the first included) keeps its bag, the same bytes as a full run's
    a, b = _bags(full), _bags(kept)
    assert {Path(k).parent.name for k in b} == {episodes[0], episodes[3]}
    assert b == {k: v for k, v in a.items() if Path(k).parent.name in (episodes[0], episodes[3])}
    # every episode keeps its partial (the kept ones too: the sample is chosen from them)
    partials = sorted(p.stem for p in (kept / "c" / PARTIAL_DIR).glob("*.arrow"))
    assert partials == sorted(episodes)
    assert read_partial(kept / "c" / PARTIAL_DIR / f"{episodes[1]}.arrow").bag == episodes[1]
    # resume: every episode is done (partials count), nothing runs again
    again = plan_run(load_params(params), "c", out=kept)
    assert again.pending == () and len(again.skipped) == 4
    # a partial or a kept bag gone (a kill, a clean-up): only that episode runs again
    gone = kept / "c" / PARTIAL_DIR / f"{episodes[2]}.arrow"
    saved = gone.read_bytes()
    gone.unlink()
    assert [e.name for e in plan_run(load_params(params), "c", out=kept).pending] == [episodes[2]]
    gone.write_bytes(saved)
    # two episodes per controller: the report shows each, so each should keep its bag
    assert sample_without_bags(again) == sorted([episodes[1], episodes[2]])
    # the campaign table from partials + sampled bags equals the one from full bags
    ra = run_report(recordings_dir=full, out_dir=tmp_path / "ra")
    rb = run_report(recordings_dir=kept, out_dir=tmp_path / "rb")
    ta = pl.read_parquet(tmp_path / "ra" / "campaigns" / "c.parquet")
    tb = pl.read_parquet(tmp_path / "rb" / "campaigns" / "c.parquet")
    assert ta.get_column("episode").n_unique() == 4
    assert tb.equals(ta)  # exactly: the same code, the same arrays
    assert ra.summary.equals(rb.summary)
    ma = json.loads((tmp_path / "ra" / "metrics.json").read_text())
    mb = json.loads((tmp_path / "rb" / "metrics.json").read_text())
    assert ma.keys() == mb.keys()
    # a bag never written has no SHA-256: the one thing that differs
    for e in (episodes[1], episodes[2]):
        assert mb["episodes"][e]["recording"]["sha256"] is None
        mb["episodes"][e]["recording"]["sha256"] = ma["episodes"][e]["recording"]["sha256"]
    for key in ma:
        assert ma[key] == mb[key], key
    bags = pl.read_csv(tmp_path / "rb" / "campaigns" / "c.bags.csv")
    assert dict(bags.iter_rows()) == {e: e in (episodes[0], episodes[3]) for e in episodes}
    assert "Bags: 2 of 4 episodes have their bag" in (tmp_path / "rb" / "report.md").read_text()
    assert not (tmp_path / "ra" / "campaigns" / "c.bags.csv").exists()
    # re-running one episode by its key writes its full bag, byte for byte
    assert [o.status for o in _run(params, kept, only=[episodes[1]])] == ["ok"]
    bag = {k: v for k, v in _bags(kept).items() if Path(k).parent.name == episodes[1]}
    assert bag and bag == {k: v for k, v in a.items() if Path(k).parent.name == episodes[1]}
    again = plan_run(load_params(params), "c", out=kept)
    assert again.pending == ()
    # a partial measured by other report code is refused, not reported
    monkeypatch.setattr(report_stage, "measure_commit", lambda: "other")
    with pytest.raises(ReportError, match="measured by other report code"):
        run_report(recordings_dir=kept, out_dir=tmp_path / "rc")


def test_keep_bags_every_k_and_unknown_episode_key(tmp_path):
    params = load_params(_params(tmp_path, {"every": 3}))
    run = plan_run(params, "c", out=tmp_path)
    names = [e.name for e in run.episodes]
    assert run.sampled and run.kept == {names[0], names[3]}
    assert not plan_run(load_params(_params(tmp_path, None)), "c", out=tmp_path).sampled
    only = plan_run(params, "c", out=tmp_path, only=[names[1]])
    assert [e.name for e in only.pending] == [names[1]] and names[1] in only.kept
    with pytest.raises(ParamsError, match="--episode nope: no such episode in campaign c"):
        plan_run(params, "c", out=tmp_path, only=["nope"])
    with pytest.raises(ParamsError, match="keep_bags"):
        load_params(_params(tmp_path, {"every": 0}))


@pytest.mark.slow
def test_record_cli_keeps_the_bags_of_the_median_and_worst(tmp_path):
    """``pipeline record --campaign -j 2`` (forked workers measure): every 4th bag, then
    the median and the worst per controller re-run by key; the report shows those from
    their bags."""
    params = _params(tmp_path, {"every": 4}, seeds=4)
    out = tmp_path / "rec"
    cmd = [sys.executable, "-m", "pipeline", "record", "--params", str(params), "--out",
           str(out), "--campaign", "c", "-j", "2"]  # fmt: skip
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    assert "keeping the bags of" in done.stderr  # median and worst per controller
    run = plan_run(load_params(params), "c", out=out)
    assert run.pending == () and sample_without_bags(run) == []
    with_bags = {p.name for p in (out / "c").iterdir() if not p.name.startswith(".")}
    names = [e.name for e in run.episodes]
    assert {names[0], names[4]} <= with_bags and len(with_bags) in (4, 5, 6)
    data = run_report(recordings_dir=out, out_dir=tmp_path / "rep")
    del data
    roles = pl.read_csv(tmp_path / "rep" / "campaigns" / "c.bags.csv")
    assert {e for e, b in roles.iter_rows() if b} == with_bags
