"""Campaign figures read without help: every axis of a metric has tick labels (log when the
values span a decade, else linear, in mrad for small angles), ECDFs rise from 0, the
baseline is drawn first in its declared colour. Checked on matplotlib's objects."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np
import polars as pl
import pytest
from matplotlib.axes import Axes
from matplotlib.axis import Axis
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from pipeline.analysis import catalog
from pipeline.analysis.campaign_tables import by_parameter
from pipeline.report.campaign_section import (
    distribution_figure,
    drawing_order,
    ecdf_figure,
    parameter_figure,
)
from pipeline.report.colors import controller_colors, mpl
from pipeline.report.figures import readable_scale

AXIS = "swept.plant.payload_kg"
CONTROLLERS = ("ctc", "ctc_pid", "pid")  # the baseline sorts last: drawing it first is a choice


def _table(*, spread: float, seeds: int = 6) -> pl.DataFrame:
    """A campaign table: two joints, three controllers, two payloads; ``max_abs_error``
    spans ``spread`` (its largest over its smallest value) on each joint."""
    rng = np.random.default_rng(1)
    rows = []
    for joint in ("shoulder", "elbow"):
        for c, controller in enumerate(CONTROLLERS):
            for payload in (0.0, 1.0):
                for seed in range(seeds):
                    share = rng.uniform(0.0, 1.0)
                    rows.append(
                        {
                            "episode": f"p{payload}.{controller}.s{seed}",
                            "condition": f"plant.payload_kg={payload}",
                            "controller": controller,
                            "seed": seed,
                            "status": "ok",
                            "joint": joint,
                            AXIS: payload,
                            "max_abs_error": 2e-4 * spread ** ((share + c) / 3),
                        }
                    )
    return pl.DataFrame(rows)


def _labels(axis: Axis) -> list[str]:
    """The labels of the major ticks inside the axis' view (what a reader sees)."""
    low, high = sorted(axis.get_view_interval())
    locs = [x for x in axis.get_majorticklocs() if low <= x <= high]
    return [text for text in axis.get_major_formatter().format_ticks(locs) if text.strip()]


def _metric_axes(fig: Figure) -> list[Axes]:
    return [ax for ax in fig.axes if ax.get_visible()]


METRIC = catalog.BY_NAME["max_abs_error"]


def _figures(table: pl.DataFrame) -> dict[str, tuple[Figure, str]]:
    colors = controller_colors(CONTROLLERS)
    conditions = sorted(set(table.get_column("condition").to_list()))
    stats = by_parameter(table, AXIS, METRIC.name)
    return {
        "distribution": (
            distribution_figure(table, METRIC, conditions, colors, "d", baseline="pid"),
            "y",
        ),
        "ecdf": (ecdf_figure(table, METRIC, colors, "e", baseline="pid"), "x"),
        "parameter": (
            parameter_figure(table, stats, AXIS, METRIC, colors, "p", baseline="pid"),
            "y",
        ),
    }


@pytest.mark.parametrize("spread", [3.0, 30.0, 1e5])
def test_every_metric_axis_has_at_least_two_tick_labels(spread: float) -> None:
    for name, (fig, which) in _figures(_table(spread=spread)).items():
        for ax in _metric_axes(fig):
            axis = ax.xaxis if which == "x" else ax.yaxis
            assert len(_labels(axis)) >= 2, (name, spread, axis.get_scale())


def test_log_only_when_the_values_span_a_decade_and_linear_small_angles_read_in_mrad() -> None:
    wide = _figures(_table(spread=1e3))
    narrow = _figures(_table(spread=2.0))
    for name in wide:
        fig, which = wide[name]
        assert all(
            (ax.get_xscale() if which == "x" else ax.get_yscale()) == "log"
            for ax in _metric_axes(fig)
        ), name
        fig, which = narrow[name]
        for ax in _metric_axes(fig):
            axis = ax.xaxis if which == "x" else ax.yaxis
            assert axis.get_scale() == "linear", name
            assert axis.get_label_text() == "Max |error| [mrad]", name
            # labels in mrad: 2e-4 rad reads about "0.2", not "2e-4" or an offset
            values = [float(t.replace("−", "-")) for t in _labels(axis)]
            assert 0.01 < max(abs(v) for v in values) < 10.0, (name, values)


def test_readable_scale_keeps_other_units_and_labels_a_log_axis_inside_one_decade() -> None:
    fig = Figure()
    ax = fig.subplots()
    # 1.2 decades that hold a single power of ten: still labelled at 1, 2 and 5
    assert readable_scale(ax, "y", np.array([2e-3, 3.2e-2]), log=True, unit="mm") == "mm"
    assert ax.get_yscale() == "log"
    assert len(_labels(ax.yaxis)) >= 3
    assert readable_scale(ax, "x", np.array([2.0, 3.0]), log=True, unit="mm") == "mm"
    assert ax.get_xscale() == "linear"


def test_ecdf_steps_rise_from_zero_to_one() -> None:
    fig, _ = _figures(_table(spread=30.0))["ecdf"]
    for ax in _metric_axes(fig):
        lines = [line for line in ax.get_lines() if len(line.get_ydata())]
        assert len(lines) == len(CONTROLLERS)
        for line in lines:
            y = np.asarray(line.get_ydata(), dtype=np.float64)
            x = np.asarray(line.get_xdata(), dtype=np.float64)
            assert y[0] == 0.0 and y[-1] == 1.0
            assert x[0] == x[1]  # the first step is vertical, at the smallest value
            assert np.all(np.diff(y) > 0)
        assert ax.get_ylim()[0] == 0.0


def test_the_baseline_is_drawn_first_in_its_declared_colour() -> None:
    assert drawing_order(CONTROLLERS, "pid") == ["pid", "ctc", "ctc_pid"]
    assert drawing_order(CONTROLLERS, "absent") == list(CONTROLLERS)
    colors = controller_colors(CONTROLLERS)
    baseline = mpl(colors["pid"])
    for name, (fig, _) in _figures(_table(spread=30.0)).items():
        for ax in _metric_axes(fig):
            first: object
            if name == "parameter":
                first = next(a for a in ax.get_children() if isinstance(a, PolyCollection))
                color = tuple(first.get_facecolor()[0][:3])
            elif name == "distribution":
                first = ax.patches[0]
                color = tuple(first.get_edgecolor()[:3])
            else:
                first = ax.get_lines()[0]
                assert isinstance(first, Line2D)
                color = matplotlib.colors.to_rgb(first.get_color())
            assert color == pytest.approx(baseline), name
        legend = fig.legends[0]
        assert [t.get_text() for t in legend.get_texts()] == ["pid", "ctc", "ctc_pid"]
        # the same colour in every figure: the registry's declared one
        assert legend.get_lines()[0].get_color() == pytest.approx(baseline)


def test_a_scenario_figures_log_error_axis_spans_a_decade_and_is_labelled() -> None:
    from pipeline.report.figures import _log_error_axis

    fig = Figure()
    ax = fig.subplots()
    ax.plot([0.0, 1.0], [3e-4, 6e-4])
    _log_error_axis(ax, 3e-4, 6e-4)  # a factor of 2 apart: widened to a decade
    low, high = ax.get_ylim()
    assert ax.get_yscale() == "log" and high / low >= 10.0
    assert len(_labels(ax.yaxis)) >= 2
