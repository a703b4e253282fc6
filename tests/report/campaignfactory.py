"""A synthetic campaign: two controllers, a swept payload, seeds (written by bagfactory)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import polars as pl

from pipeline.analysis import catalog
from pipeline.settings import CampaignInfo
from tests.analysis.bagfactory import Episode, paper_like, write_bag

PAYLOADS_KG = (0.0, 0.5, 1.0)


def campaign_episodes(
    name: str = "sweep", *, seeds: int = 4, payloads: tuple[float, ...] = PAYLOADS_KG
) -> list[Episode]:
    """``name`` over pid and ctc x payloads x seeds. PID's error grows slowly with the
    payload, CTC's quickly (it starts 4x smaller and ends 2x larger): CTC stops winning
    between 0.5 and 1 kg."""
    out = []
    for payload in payloads:
        condition = f"plant.payload_kg={payload:g}"
        for seed in range(seeds):
            for ctrl, scale in (
                ("pid", 2e-3 * (1 + 0.2 * payload)),
                ("ctc", 0.5e-3 * (1 + 7.0 * payload)),
            ):
                ep = paper_like(
                    f"{name}-{ctrl}-p{payload:g}-s{seed}",
                    ctrl,
                    duration_s=0.3,
                    motion_end_s=0.2,
                    error_scale=scale * (1 + 0.05 * seed),
                    seed=seed,
                    scenario="paper-realistic",
                )
                ep.campaign = CampaignInfo(
                    name=name,
                    condition=condition,
                    swept={"controller": ctrl, "seed": seed, "plant.payload_kg": payload},
                )
                out.append(ep)
    return out


def write_campaign(root: Path, episodes: list[Episode]) -> Path:
    """Bags under ``root/<campaign>/<episode>/`` (the campaign layout); returns ``root``."""
    for ep in episodes:
        assert ep.campaign is not None
        folder = root / ep.campaign.name
        folder.mkdir(parents=True, exist_ok=True)
        write_bag(folder, ep)
    return root


def table_row(
    cond: str, controller: str, seed: int, joint: str, max_abs_error: float
) -> dict[str, Any]:
    """One row of a campaign table (episode x joint) of ``campaign`` c: the max error given,
    RMS half of it, final a tenth, every other metric empty."""
    row: dict[str, Any] = dict.fromkeys(catalog.METRIC_COLUMNS)
    row.update(
        max_abs_error=max_abs_error, rms_error=max_abs_error / 2, final_error=max_abs_error / 10
    )
    return {
        "episode": f"{cond}-{controller}-{seed}",
        "campaign": "c",
        "condition": cond,
        "controller": controller,
        "seed": seed,
        "status": "ok",
        "joint": joint,
        **row,
    }


def table_frame(rows: list[dict[str, Any]]) -> pl.DataFrame:
    """Rows of :func:`table_row` as the campaign table (metrics as Float64)."""
    return pl.DataFrame(rows, schema_overrides={m: pl.Float64 for m in catalog.METRIC_COLUMNS})
