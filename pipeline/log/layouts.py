"""Foxglove and PlotJuggler layouts for our bags: per joint, the reference vs the true and
the measured position, the error against the true state (what the metrics use) beside the
controller's own (against the measured state), and the applied vs the commanded effort; in
Foxglove also the arm in 3D from ``/robot_description`` and ``/tf``, following the flange.

One list of plots (:data:`PLOTS`, of topics of :data:`pipeline.log.topics.TOPICS`) is written in
each viewer's path syntax:

- Foxglove message paths: ``/controller_state.reference.positions[0]``,
  ``/joint_states.position[0]`` (arrays by index, in the bag's joint order);
- PlotJuggler series names: ``/controller_state/reference/positions[0]``, and
  ``/joint_states/shoulder_pan_joint/position`` (PlotJuggler names a JointState's series by
  joint name).

The true-state error is not a recorded field: it is computed in the viewer from two recorded
ones (a :class:`Difference`), in Foxglove by a user script saved in the layout (its output
topic ``/foxglove_script/<name>``, one array element per joint), in PlotJuggler by a custom
math series per joint (``<name>/<joint>``, Lua ``return value - v1``). The bag holds no
TCP error (the report's ``recording.rrd`` has it) and ``/tf`` is the measured state's.

``python -m pipeline.log.layouts [FOLDER]`` writes ``foxglove.json`` and
``plotjuggler.xml`` (default folder ``layouts/``, what the repository ships, for the UR5);
``pipeline layouts --bag B --out DIR`` writes them for one bag's joints and topics
(:func:`bag_plots`; ours or any robot's);
``tests/log/test_layouts.py`` checks the shipped files are these, and that every topic,
field and script input in them exists in a bag ``pipeline record`` writes.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Collection, Mapping
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

from pipeline.constants import (
    TOPIC_CONTROLLER_STATE,
    TOPIC_GROUND_TRUTH,
    TOPIC_JOINT_STATES,
    TOPIC_ROBOT_DESCRIPTION,
    TYPE_JOINT_STATE,
)
from pipeline.log.topics import TOPICS
from pipeline.robots.chain import FLANGE

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
_TRUE_ERROR = "#d62728"
# Foxglove publishes a user script's output on a topic under this prefix (Foxglove Studio
# 1.x and Lichtblick: /studio_script/).
FOXGLOVE_SCRIPT_PREFIX = "/foxglove_script/"
# The field of a Difference script's output message: one element per joint.
SCRIPT_FIELD = "error"


@dataclass(frozen=True)
class Source:
    """A recorded per-joint array: ``topic``'s field path ``fields``."""

    topic: str
    fields: tuple[str, ...]
    type: str = ""
    """The topic's message type ("": our topic of that name's, :data:`TOPICS`)."""


@dataclass(frozen=True)
class Difference:
    """``minuend − subtrahend`` per joint, computed in the viewer (recorded at the same
    stamps); ``name`` names the Foxglove script's topic and the PlotJuggler series."""

    name: str
    minuend: Source
    subtrahend: Source


@dataclass(frozen=True)
class Curve:
    """One plotted value at the joint's index: a recorded array or a :class:`Difference`."""

    value: Source | Difference
    label: str
    color: str


# reference − true position: the error the metrics use (the controller sees the measured one)
TRUE_STATE_ERROR = Difference(
    "true_state_error",
    Source(TOPIC_CONTROLLER_STATE, ("reference", "positions")),
    Source(TOPIC_GROUND_TRUTH, ("position",)),
)


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
            Curve(
                Source(TOPIC_CONTROLLER_STATE, ("reference", "positions")), "reference", _REFERENCE
            ),
            Curve(Source(TOPIC_GROUND_TRUTH, ("position",)), "true", _TRUE),
            Curve(Source(TOPIC_JOINT_STATES, ("position",)), "measured", _MEASURED),
        ),
    ),
    Plot(
        "error [rad]: reference − true (the metrics'), reference − measured (the controller's)",
        (
            Curve(TRUE_STATE_ERROR, "reference − true", _TRUE_ERROR),
            Curve(
                Source(TOPIC_CONTROLLER_STATE, ("error", "positions")),
                "reference − measured",
                _MEASURED,
            ),
        ),
    ),
    Plot(
        "effort [N m]",
        (
            Curve(Source(TOPIC_JOINT_STATES, ("effort",)), "applied", _MEASURED),
            Curve(Source(TOPIC_CONTROLLER_STATE, ("output", "effort")), "commanded", _COMMANDED),
        ),
    ),
)


def differences(plots: tuple[Plot, ...] = PLOTS) -> tuple[Difference, ...]:
    """The :class:`Difference` values ``plots`` draw, in order, each once."""
    found = [c.value for p in plots for c in p.curves if isinstance(c.value, Difference)]
    return tuple(dict.fromkeys(found))


def _type(source: Source) -> str:
    if source.type:
        return source.type
    (row,) = [t for t in TOPICS if t.name == source.topic]
    return row.type


def bag_plots(
    present: Collection[str], remaps: Mapping[str, str] | None = None
) -> tuple[tuple[Plot, ...], tuple[str, ...]]:
    """:data:`PLOTS` for one bag, and our topics it lacks.

    Args:
        present: the bag's topics.
        remaps: role -> the bag's topic (``--topic``, roles as the reader's), for a bag whose
            topics are not ours (``/arm_controller/controller_state``).

    A curve on a topic the bag lacks is left out (a :class:`Difference` when either input
    is), and a plot left without curves.
    """
    by_name = {t.name: (remaps or {}).get(str(t.role), t.name) for t in TOPICS}
    missing: dict[str, None] = {}

    def mapped(source: Source) -> Source | None:
        topic = by_name.get(source.topic, source.topic)
        if topic not in present:
            missing[source.topic] = None
            return None
        return Source(topic, source.fields, _type(source))

    plots = []
    for plot in PLOTS:
        curves = []
        for c in plot.curves:
            if isinstance(c.value, Difference):
                a, b = mapped(c.value.minuend), mapped(c.value.subtrahend)
                if a is not None and b is not None:
                    curves.append(Curve(Difference(c.value.name, a, b), c.label, c.color))
            elif (source := mapped(c.value)) is not None:
                curves.append(Curve(source, c.label, c.color))
        if curves:
            plots.append(Plot(plot.title, tuple(curves)))
    return tuple(plots), tuple(missing)


def script_topic(diff: Difference) -> str:
    """The topic Foxglove publishes ``diff``'s user script output on."""
    return f"{FOXGLOVE_SCRIPT_PREFIX}{diff.name}"


def foxglove_path(curve: Curve, index: int) -> str:
    """Foxglove's message path of ``curve`` for the joint at ``index``."""
    if isinstance(curve.value, Difference):
        return f"{script_topic(curve.value)}.{SCRIPT_FIELD}[{index}]"
    return f"{curve.value.topic}.{'.'.join(curve.value.fields)}[{index}]"


def _pj_series(source: Source, index: int, joint: str) -> str:
    if _type(source) == TYPE_JOINT_STATE:
        (leaf,) = source.fields
        return f"{source.topic}/{joint}/{leaf}"
    return f"{source.topic}/{'/'.join(source.fields)}[{index}]"


def plotjuggler_name(curve: Curve, index: int, joint: str) -> str:
    """PlotJuggler's series name of ``curve`` for ``joint`` (at ``index``)."""
    if isinstance(curve.value, Difference):
        return f"{curve.value.name}/{joint}"
    return _pj_series(curve.value, index, joint)


def _ts_path(source: Source) -> str:
    return ".".join(source.fields)


def foxglove_script(diff: Difference) -> str:
    """The TypeScript user script publishing ``diff`` per joint on :func:`script_topic`: the
    latest message of each input, subtracted when both carry the same header stamp."""
    a, b = diff.minuend, diff.subtrahend
    inputs = json.dumps([a.topic, b.topic])
    return f"""\
// {diff.name}: {a.topic} {_ts_path(a)} − {b.topic} {_ts_path(b)}, per joint
// (written by `python -m pipeline.log.layouts`, armlab pipeline).
import {{ Input }} from "./types";

type Stamp = {{ sec: number; nsec?: number; nanosec?: number }};
type Latest = {{ stamp: string; values: ArrayLike<number> }};
type Output = {{ {SCRIPT_FIELD}: number[] }};

export const inputs = {inputs};
export const output = "{script_topic(diff)}";

let minuend: Latest | undefined;
let subtrahend: Latest | undefined;

function key(stamp: Stamp): string {{
  return `${{stamp.sec}}.${{stamp.nsec ?? stamp.nanosec ?? 0}}`;
}}

export default function script(
  event: Input<"{a.topic}"> | Input<"{b.topic}">,
): Output | undefined {{
  switch (event.topic) {{
    case "{a.topic}":
      minuend = {{
        stamp: key(event.message.header.stamp),
        values: event.message.{_ts_path(a)},
      }};
      break;
    case "{b.topic}":
      subtrahend = {{
        stamp: key(event.message.header.stamp),
        values: event.message.{_ts_path(b)},
      }};
      break;
  }}
  if (minuend === undefined || subtrahend === undefined || minuend.stamp !== subtrahend.stamp) {{
    return undefined;
  }}
  const n = Math.min(minuend.values.length, subtrahend.values.length);
  const {SCRIPT_FIELD}: number[] = [];
  for (let i = 0; i < n; i++) {{
    {SCRIPT_FIELD}.push(minuend.values[i] - subtrahend.values[i]);
  }}
  return {{ {SCRIPT_FIELD} }};
}}
"""


THREE_D_PANEL = "3D!tcp"


def three_d_config() -> dict[str, object]:
    """Foxglove's 3D panel: the robot from the URDF on ``/robot_description``, posed by
    ``/tf`` (the measured joint positions), the view following the flange frame."""
    return {
        "followTf": FLANGE,
        "followMode": "follow-position",
        "layers": {"grid": {"layerId": "foxglove.Grid", "visible": True, "frameLocked": True}},
        # the 3D panel draws a std_msgs/String URDF topic of this name when it is visible
        "topics": {TOPIC_ROBOT_DESCRIPTION: {"visible": True}},
        "transforms": {f"frame:{FLANGE}": {"visible": True}},
    }


def foxglove_layout(
    joints: tuple[str, ...] = UR5_JOINTS, plots: tuple[Plot, ...] = PLOTS
) -> dict[str, object]:
    """A Foxglove layout (Layouts → Import from file): a tab per joint, its plots stacked."""
    config: dict[str, object] = {}
    tabs = []
    for j, joint in enumerate(joints):
        ids = []
        for k, plot in enumerate(plots):
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
    config[THREE_D_PANEL] = three_d_config()
    tabs.append({"title": f"3D ({FLANGE})", "layout": THREE_D_PANEL})
    config["Tab!joints"] = {"activeTabIdx": 0, "tabs": tabs}
    scripts = {
        f"{FOXGLOVE_SCRIPT_PREFIX.strip('/')}_{d.name}": {
            "name": d.name,
            "sourceCode": foxglove_script(d),
        }
        for d in differences(plots)
    }
    return {
        "configById": config,
        "globalVariables": {},
        "userNodes": scripts,
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


def plotjuggler_layout(
    joints: tuple[str, ...] = UR5_JOINTS, plots: tuple[Plot, ...] = PLOTS
) -> str:
    """A PlotJuggler layout (File → Load layout, with the MCAP loaded): a tab per joint."""
    lines = ["<?xml version='1.0' encoding='UTF-8'?>", "<root>"]
    lines.append(' <tabbed_widget name="Main Window" parent="main_window">')
    n = len(plots)
    sizes = ";".join([f"{1 / n:.6f}"] * n)
    for j, joint in enumerate(joints):
        lines.append(f'  <Tab containers="1" tab_name={quoteattr(f"{j + 1} {joint}")}>')
        lines.append("   <Container>")
        lines.append(f'    <DockSplitter orientation="-" count="{n}" sizes="{sizes}">')
        for plot in plots:
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
    lines.extend(_pj_snippets(joints, plots))
    lines.append(" <snippets/>")
    lines.append("</root>")
    return "\n".join(lines) + "\n"


def _pj_snippets(joints: tuple[str, ...], plots: tuple[Plot, ...]) -> list[str]:
    """PlotJuggler's custom math series: per :class:`Difference` and joint, ``value`` (the
    minuend's series) minus ``v1`` (the subtrahend's), in Lua."""
    lines = [" <customMathEquations>"]
    for d in differences(plots):
        for j, joint in enumerate(joints):
            lines.append(f"  <snippet name={quoteattr(f'{d.name}/{joint}')}>")
            lines.append("   <global></global>")
            lines.append("   <function>return value - v1</function>")
            minuend = escape(_pj_series(d.minuend, j, joint))
            lines.append(f"   <linked_source>{minuend}</linked_source>")
            lines.append("   <additional_sources>")
            lines.append(f"    <v1>{escape(_pj_series(d.subtrahend, j, joint))}</v1>")
            lines.append("   </additional_sources>")
            lines.append("  </snippet>")
    lines.append(" </customMathEquations>")
    return lines


def write_layouts(
    folder: Path, joints: tuple[str, ...] = UR5_JOINTS, plots: tuple[Plot, ...] = PLOTS
) -> list[Path]:
    """Write both layouts (for ``joints``, drawing ``plots``) into ``folder``; return their
    paths."""
    folder.mkdir(parents=True, exist_ok=True)
    from pipeline.fsutil import atomic_write_bytes

    fox = folder / FOXGLOVE_FILE
    text = json.dumps(foxglove_layout(joints, plots), indent=2, ensure_ascii=False) + "\n"
    atomic_write_bytes(fox, text.encode("utf-8"))
    pj = folder / PLOTJUGGLER_FILE
    atomic_write_bytes(pj, plotjuggler_layout(joints, plots).encode("utf-8"))
    return [fox, pj]


def main(argv: list[str] | None = None) -> None:
    """``python -m pipeline.log.layouts [FOLDER]``: write the UR5's layouts (what ships)."""
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m pipeline.log.layouts",
        description="Write the Foxglove and PlotJuggler layouts for the UR5's bags "
        f"({FOXGLOVE_FILE}, {PLOTJUGGLER_FILE}).",
    )
    parser.add_argument(
        "folder", nargs="?", default=DEFAULT_FOLDER, help=f"where (default: {DEFAULT_FOLDER}/)"
    )
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    for written in write_layouts(Path(args.folder)):
        print(written)


if __name__ == "__main__":  # pragma: no cover
    main()
