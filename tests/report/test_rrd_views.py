"""What recording.rrd shows at a glance: a plain-text colour key, errors in mrad against the
state the metrics use, y axes with readable ticks, and no 3D view without a robot model."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rerun.blueprint as rrb

from pipeline.report import entities as ent
from pipeline.report import rerun_rrd
from pipeline.stages.report import run_report
from tests.analysis.bagfactory import paper_like, write_bag


def _views(container: Any) -> list[Any]:
    """Every view under a blueprint container."""
    out = []
    for item in container.contents:
        out += _views(item) if isinstance(item, rrb.Container) else [item]
    return out


def _report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, **episode: Any
) -> tuple[Path, list[Any]]:
    """Report two bags; return the .rrd and the views of the blueprint it was written with."""
    built: list[rrb.Blueprint] = []
    real = rerun_rrd.blueprint

    def spy(*args: Any, **kwargs: Any) -> rrb.Blueprint:
        built.append(real(*args, **kwargs))
        return built[-1]

    monkeypatch.setattr(rerun_rrd, "blueprint", spy)
    for name, ctrl, scale in (("pid_paper", "pid", 3.3e-3), ("ctc_paper", "ctc", 1.8e-3)):
        ep = paper_like(name, ctrl, error_scale=scale)
        for key, value in episode.items():
            setattr(ep, key, value)
        write_bag(tmp_path / "recordings", ep)
    # a bag without our metadata is its own controller, named after it
    baseline = "pid" if episode.get("episode_metadata", True) else "pid_paper"
    result = run_report(
        recordings_dir=tmp_path / "recordings", out_dir=tmp_path / "reports", baseline=baseline
    )
    (layout,) = built
    return result.out_dir / "recording.rrd", _views(layout.root_container)


@pytest.fixture(scope="module")
def default(tmp_path_factory: pytest.TempPathFactory) -> tuple[list[str], list[Any]]:
    """One report of the two default bags, shared: its text documents and its views."""
    logged: list[str] = []
    real = rerun_rrd.rr.TextDocument

    def spy(text: str, **kwargs: Any) -> Any:
        logged.append(text)
        return real(text, **kwargs)

    with pytest.MonkeyPatch.context() as monkeypatch:
        monkeypatch.setattr(rerun_rrd.rr, "TextDocument", spy)
        _, views = _report(tmp_path_factory.mktemp("default"), monkeypatch)
    return logged, views


def test_colour_key_is_plain_text_naming_each_colour(
    default: tuple[list[str], list[Any]],
) -> None:
    logged, _ = default
    (key,) = logged  # the .rrd's one text document (its bytes are LZ4-compressed)
    assert "<" not in key and "style=" not in key  # Rerun's text view renders no HTML
    assert "**ctc**: orange (#ff7f0e)" in key and "**pid**: blue (#1f77b4)" in key
    assert "reference: light grey" in key


def test_no_3d_view_when_no_bag_holds_a_robot_model(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, default: tuple[list[str], list[Any]]
) -> None:
    _, with_robot = default
    assert any(isinstance(v, rrb.Spatial3DView) for v in with_robot)
    _, foreign = _report(tmp_path / "foreign", monkeypatch, episode_metadata=False)
    assert not any(isinstance(v, rrb.Spatial3DView) for v in foreign)
    assert any(isinstance(v, rrb.TextDocumentView) for v in foreign)  # the key stays


def _title(view: Any) -> str:
    return str(view.name)


def test_error_views_are_in_mrad_against_the_state_the_metrics_use(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, default: tuple[list[str], list[Any]]
) -> None:
    _, measured = default
    titles = [_title(v) for v in measured]
    assert any("error = reference − measured state [mrad]" in t for t in titles), titles
    n = len(paper_like("x", "pid").stamp_ns)
    q_true = paper_like("x", "pid").q + 1e-6 * np.ones((n, 6))
    _, true = _report(tmp_path / "true", monkeypatch, q_true=q_true)
    titles = [_title(v) for v in true]
    assert any("error = reference − true state [mrad]" in t for t in titles), titles
    assert not any("measured" in t for t in titles)


def _ticks(lo: float, hi: float) -> list[float]:
    """The ticks Rerun labels in [lo, hi]: multiples of the largest power of ten that has
    at least two of them there."""
    k = math.floor(math.log10(hi - lo))
    while True:
        step = 10.0**k
        ticks = [
            i * step for i in range(math.ceil(lo / step - 1e-9), math.floor(hi / step + 1e-9) + 1)
        ]
        if len(ticks) >= 2:
            return ticks
        k -= 1


@pytest.mark.parametrize(
    ("lo", "hi"),
    [
        (-0.3, 0.3),
        (-0.32, 0.05),
        (0.0, 1.7e-4),
        (-3.1, 2.9),
        (-1.15, -0.9),
        (0.0, 0.0),
        (5e-7, 5e-7),
    ],
)
def test_readable_range_holds_the_data_with_two_to_four_ticks(lo: float, hi: float) -> None:
    a, b = rerun_rrd.readable_range(lo, hi)
    assert a <= lo and hi <= b and a < b
    # ticks of the range's own power of ten: between 2 and 4, none at the clipped edge
    pad = rerun_rrd.RANGE_PAD / (1 + 2 * rerun_rrd.RANGE_PAD) * (b - a)
    inner = _ticks(a + pad, b - pad)
    assert 2 <= len(inner) <= 4, (a, b, inner)


def test_error_and_effort_views_get_a_readable_range(
    default: tuple[list[str], list[Any]],
) -> None:
    _, views = default
    by_origin = {str(v.origin): v for v in views if isinstance(v, rrb.TimeSeriesView)}
    for q in ("error", "effort"):
        view = by_origin[ent.quantity_path("shoulder_lift_joint", q)]
        assert view.properties.get("ScalarAxis") is not None, q
