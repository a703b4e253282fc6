"""Foxglove and PlotJuggler layouts for our bags: per joint, the reference vs the true and
the measured position, the controller's error, and the applied vs the commanded effort.

One list of plots (:data:`PLOTS`, of topics of :data:`pipeline.log.topics.TOPICS`) is written in
each viewer's path syntax:

- Foxglove message paths: ``/controller_state.reference.positions[0]``,
  ``/joint_states.position[0]`` (arrays by index, in the bag's joint order);
- PlotJuggler series names: ``/controller_state/reference/positions[0]``, and
  ``/joint_states/shoulder_pan_joint/position`` (PlotJuggler names a JointState's series by
  joint name).

``python -m pipeline.log.layouts [FOLDER]`` writes ``foxglove.json`` and
``plotjuggler.xml`` (default folder ``layouts/``, what the repository ships, for the UR5);
``tests/log/test_layouts.py`` checks the shipped files are these, and that every path in
them exists in a bag ``pipeline record`` writes. The true-state error (reference − true
position, what the metrics use) is not a recorded field: plot both positions, or see the
report's ``recording.rrd``; a TCP error is not in the bag either.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import quoteattr

from pipeline.constants import (
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TYPE_JOINT_STATE,
)
from pipeline.log.topics import TOPICS

FOXGLOVE_FILE = "foxglove.json"
PLOTJUGGLER_FILE = "plotjuggler.xml"
DEFAULT_FOLDER = "layouts"
# The robot the shipped layouts are for (PlotJuggler names JointState series by joint).
UR5_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
# Colours as in the report: the reference light grey, then tab10.
_REFERENCE = "#c8c8c8"
_TRUE = "#2ca02c"
_MEASURED = "#1f77b4"
_COMMANDED = "#ff7f0e"


@dataclass(frozen=True)
class Curve:
    """One plotted value: ``topic``'s array ``fields`` (a path of message fields) at the
    joint's index."""

    topic: str
    fields: tuple[str, ...]
    label: str
    color: str


@dataclass(frozen=True)
class Plot:
    """One plot of a joint's tab."""

    title: str
    curves: tuple[Curve, ...]


# The plots of each joint's tab, top to bottom.
PLOTS = (
    Plot(
        "position [rad]",
        (
            Curve(TOPIC_CONTROLLER_STATE, ("reference", "positions"), "reference", _REFERENCE),
            Curve(TOPIC_GROUND_TRUTH, ("position",), "true", _TRUE),
            Curve(TOPIC_JOINT_STATES, ("position",), "measured", _MEASURED),
        ),
    ),
    Plot(
        "error = reference − measured [rad] (the controller's)",
        (Curve(TOPIC_CONTROLLER_STATE, ("error", "positions"), "error", _MEASURED),),
    ),
    Plot(
        "effort [N m]",
        (
            Curve(TOPIC_JOINT_STATES, ("effort",), "applied", _MEASURED),
            Curve(TOPIC_CONTROLLER_STATE, ("output", "effort"), "commanded", _COMMANDED),
        ),
    ),
)


def _type(topic: str) -> str:
    (row,) = [t for t in TOPICS if t.name == topic]
    return row.type


def foxglove_path(curve: Curve, index: int) -> str:
    """Foxglove's message path of ``curve`` for the joint at ``index``."""
    return f"{curve.topic}.{'.'.join(curve.fields)}[{index}]"


def plotjuggler_name(curve: Curve, index: int, joint: str) -> str:
    """PlotJuggler's series name of ``curve`` for ``joint`` (at ``index``)."""
    if _type(curve.topic) == TYPE_JOINT_STATE:
        (leaf,) = curve.fields
        return f"{curve.topic}/{joint}/{leaf}"
    return f"{curve.topic}/{'/'.join(curve.fields)}[{index}]"


def foxglove_layout(joints: tuple[str, ...] = UR5_JOINTS) -> dict[str, object]:
    """A Foxglove layout (Layouts → Import from file): a tab per joint, its plots stacked."""
    config: dict[str, object] = {}
    tabs = []
    for j, joint in enumerate(joints):
        ids = []
        for k, plot in enumerate(PLOTS):
            panel = f"Plot!{joint}_{k}"
            ids.append(panel)
            config[panel] = {
                "title": f"{joint}: {plot.title}",
                "paths": [
                    {
                        "value": foxglove_path(c, j),
                        "enabled": True,
                        "timestampMethod": "receiveTime",
                        "label": c.label,
                        "color": c.color,
                    }
                    for c in plot.curves
                ],
                "showXAxisLabels": True,
                "showYAxisLabels": True,
                "showLegend": True,
                "legendDisplay": "floating",
                "isSynced": True,
                "xAxisVal": "timestamp",
            }
        tabs.append({"title": f"{j + 1} {joint}", "layout": _column(ids)})
    config["Tab!joints"] = {"activeTabIdx": 0, "tabs": tabs}
    return {
        "configById": config,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": {"speed": 1},
        "layout": "Tab!joints",
    }


def _column(ids: list[str]) -> object:
    """Foxglove's nested split of ``ids``, stacked with equal heights."""
    if len(ids) == 1:
        return ids[0]
    return {
        "direction": "column",
        "first": ids[0],
        "second": _column(ids[1:]),
        "splitPercentage": 100.0 / len(ids),
    }


def plotjuggler_layout(joints: tuple[str, ...] = UR5_JOINTS) -> str:
    """A PlotJuggler layout (File → Load layout, with the MCAP loaded): a tab per joint."""
    lines = ["<?xml version='1.0' encoding='UTF-8'?>", "<root>"]
    lines.append(' <tabbed_widget name="Main Window" parent="main_window">')
    n = len(PLOTS)
    sizes = ";".join([f"{1 / n:.6f}"] * n)
    for j, joint in enumerate(joints):
        lines.append(f'  <Tab containers="1" tab_name={quoteattr(f"{j + 1} {joint}")}>')
        lines.append("   <Container>")
        lines.append(f'    <DockSplitter orientation="-" count="{n}" sizes="{sizes}">')
        for plot in PLOTS:
            lines.append(f"     <DockArea name={quoteattr(f'{joint}: {plot.title}')}>")
            lines.append(
                '      <plot mode="TimeSeries" style="Lines" flip_x="false" flip_y="false">'
            )
            lines.append('       <range left="0" right="1" top="1" bottom="0"/>')
            lines.append("       <limitY/>")
            for c in plot.curves:
                name = plotjuggler_name(c, j, joint)
                lines.append(f"       <curve name={quoteattr(name)} color={quoteattr(c.color)}/>")
            lines.append("      </plot>")
            lines.append("     </DockArea>")
        lines.append("    </DockSplitter>")
        lines.append("   </Container>")
        lines.append("  </Tab>")
    lines.append('  <currentTabIndex index="0"/>')
    lines.append(" </tabbed_widget>")
    lines.append(' <use_relative_time_offset enabled="1"/>')
    lines.append(" <Plugins>")
    lines.append('  <plugin ID="DataLoad MCAP"/>')
    lines.append(" </Plugins>")
    lines.append(" <previouslyLoaded_Datafiles/>")
    lines.append(" <customMathEquations/>")
    lines.append(" <snippets/>")
    lines.append("</root>")
    return "\n".join(lines) + "\n"


def write_layouts(folder: Path) -> list[Path]:
    """Write both layouts into ``folder``; return their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    fox = folder / FOXGLOVE_FILE
    fox.write_text(json.dumps(foxglove_layout(), indent=2, ensure_ascii=False) + "\n", "utf-8")
    pj = folder / PLOTJUGGLER_FILE
    pj.write_text(plotjuggler_layout(), encoding="utf-8")
    return [fox, pj]


if __name__ == "__main__":  # pragma: no cover - python -m pipeline.log.layouts [FOLDER]
    for written in write_layouts(Path(sys.argv[1] if len(sys.argv) > 1 else DEFAULT_FOLDER)):
        print(written)
