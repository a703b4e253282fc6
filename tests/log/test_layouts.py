"""The Foxglove and PlotJuggler layouts we ship open our bags: every topic and field path
they name, every user script's inputs and message fields and every custom math series'
sources exist in a bag `pipeline record` writes (and a wrong name fails the check)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from pipeline.constants import TOPIC_JOINT_STATES, TOPIC_TF, TYPE_JOINT_STATE, TYPE_STRING
from pipeline.log import layouts
from pipeline.log.msgdef import MsgField, MsgTypes, parse_msgdef, root_type_name
from pipeline.log.topics import TOPICS

REPO = Path(__file__).parents[2]
SHIPPED = REPO / layouts.DEFAULT_FOLDER
_INDEXED = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*)(\[(?P<index>\d+)\])?$")


class Bag:
    """What a layout may name in a recorded bag: topics, their types, the joints."""

    def __init__(self, mcap: Path) -> None:
        with open(mcap, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            summary = reader.get_summary()
            assert summary is not None
            self.types: dict[str, MsgTypes] = {}
            self.root: dict[str, str] = {}
            for ch in summary.channels.values():
                schema = summary.schemas[ch.schema_id]
                self.types[ch.topic] = parse_msgdef(schema.name, schema.data.decode())
                self.root[ch.topic] = root_type_name(schema.name)
            _, _, _, msg = next(reader.iter_decoded_messages(topics=[TOPIC_JOINT_STATES]))
            self.joints = tuple(msg.name)
            _, _, _, tf = next(reader.iter_decoded_messages(topics=[TOPIC_TF]))
            self.frames = {t.child_frame_id for t in tf.transforms}

    def topic_of(self, path: str, sep: str) -> tuple[str, list[str]]:
        """The longest recorded topic ``path`` starts with, and the rest split at ``sep``."""
        topics = [t for t in self.types if path.startswith(t + sep)]
        assert topics, f"{path}: no recorded topic (recorded: {sorted(self.types)})"
        topic = max(topics, key=len)
        return topic, path[len(topic) + 1 :].split(sep)

    def field(self, topic: str, path: str) -> MsgField:
        """The field a dotted ``path`` (no indices) names in the topic's message."""
        assert topic in self.types, f"{topic}: not recorded (recorded: {sorted(self.types)})"
        types, type_name = self.types[topic], self.root[topic]
        field = None
        for name in path.split("."):
            assert type_name in types, f"{topic}: {path}: {type_name} has no fields"
            fields = {f.name: f for f in types[type_name].fields}
            assert name in fields, f"{topic}: {type_name} has no field {name!r}"
            field = fields[name]
            type_name = field.base
        assert field is not None, path
        return field

    def check_fields(self, topic: str, parts: list[str]) -> None:
        """``parts`` (``name`` or ``name[i]``) walk the topic's message down to a number."""
        types, type_name = self.types[topic], self.root[topic]
        for k, part in enumerate(parts):
            m = _INDEXED.match(part)
            assert m, f"{topic}: bad field {part!r}"
            fields = {f.name: f for f in types[type_name].fields}
            assert m["name"] in fields, f"{topic}: {type_name} has no field {m['name']!r}"
            field = fields[m["name"]]
            assert (field.array is not None) == (m["index"] is not None), f"{topic}: {part}"
            if m["index"] is not None:
                assert int(m["index"]) < len(self.joints), f"{topic}: {part}: past the joints"
            if k == len(parts) - 1:
                assert field.base in ("float64", "float32"), f"{topic}: {part} is not a number"
            else:
                type_name = field.base


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Bag:
    tmp = tmp_path_factory.mktemp("layouts")
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["scenarios"]["paper"]["hold_s"] = 0.1
    params = tmp / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    out = tmp / "rec"
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "record", "--params", str(params), "-o", str(out),
         "--only", "paper-ctc"],
        capture_output=True, text=True, timeout=600, cwd=REPO,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    (mcap,) = (out / "paper-ctc").glob("*.mcap")
    return Bag(mcap)


def test_shipped_layouts_are_the_generated_ones(tmp_path: Path) -> None:
    for written in layouts.write_layouts(tmp_path):
        assert (SHIPPED / written.name).read_text(encoding="utf-8") == written.read_text(
            encoding="utf-8"
        ), f"regenerate with `python -m pipeline.log.layouts` ({written.name})"


def test_layouts_name_only_recorded_topics_of_the_topic_table() -> None:
    ours = {t.name for t in TOPICS}
    for plot in layouts.PLOTS:
        for curve in plot.curves:
            value = curve.value
            sources = (
                [value.minuend, value.subtrahend]
                if isinstance(value, layouts.Difference)
                else [value]
            )
            assert all(s.topic in ours for s in sources), curve


_EXPORT = re.compile(r"^export const (?P<name>inputs|output) = (?P<value>.+);$", re.M)
_OUTPUT_TYPE = re.compile(r"^type Output = \{ (?P<field>\w+): number\[\] \};$", re.M)
_CASE = re.compile(r'case "(?P<topic>[^"]+)":(?P<body>.*?)break;', re.S)
_MESSAGE_FIELD = re.compile(r"(?P<key>\w+): (?:key\()?event\.message\.(?P<path>[\w.]+)")


def check_script(source: str, bag: Bag) -> tuple[str, str]:
    """A user script's inputs are recorded topics, each of its message fields exists (the
    stamp a header's Time, the values a float64 array); returns (output topic, its field)."""
    exports = {m["name"]: json.loads(m["value"]) for m in _EXPORT.finditer(source)}
    assert set(exports) == {"inputs", "output"}, exports
    inputs, output = exports["inputs"], exports["output"]
    assert output.startswith(layouts.FOXGLOVE_SCRIPT_PREFIX), output
    cases = {m["topic"]: m["body"] for m in _CASE.finditer(source)}
    assert sorted(cases) == sorted(inputs), f"script cases {sorted(cases)} vs inputs {inputs}"
    for topic in inputs:
        assert topic in bag.types, f"script input {topic}: not recorded ({sorted(bag.types)})"
        used = {m["key"]: m["path"] for m in _MESSAGE_FIELD.finditer(cases[topic])}
        assert set(used) == {"stamp", "values"}, f"{topic}: {used}"
        assert bag.field(topic, used["stamp"]).base == "builtin_interfaces/msg/Time", used
        values = bag.field(topic, used["values"])
        assert values.base == "float64" and values.array is not None, f"{topic}: {values}"
    out_type = _OUTPUT_TYPE.search(source)
    assert out_type, "no `type Output = { <field>: number[] };`"
    assert f"return {{ {out_type['field']} }};" in source
    return output, out_type["field"]


def check_foxglove(doc: dict[str, Any], bag: Bag) -> int:
    """Every plotted path, script and 3D layer of a Foxglove layout resolves in ``bag``;
    returns the number of plotted paths."""
    outputs = dict(check_script(s["sourceCode"], bag) for s in doc["userNodes"].values())
    config = doc["configById"]
    paths = [p["value"] for panel in config.values() for p in panel.get("paths", [])]
    for path in paths:
        scripted = [t for t in outputs if path.startswith(t + ".")]
        if scripted:
            m = _INDEXED.match(path[len(scripted[0]) + 1 :])
            assert m and m["name"] == outputs[scripted[0]] and m["index"], path
            assert int(m["index"]) < len(bag.joints), f"{path}: past the joints"
            continue
        topic, parts = bag.topic_of(path, ".")
        bag.check_fields(topic, parts)
    for key, panel in config.items():
        if key.startswith("3D!"):
            assert panel["followTf"] in bag.frames, f"{panel['followTf']}: not in /tf"
            for topic in panel["topics"]:  # the URDF
                assert bag.root.get(topic) == TYPE_STRING, f"{topic}: not a recorded String"
    # every panel the tabs lay out is configured, and every configured panel is laid out
    laid_out: set[str] = set()

    def walk(node: object) -> None:
        if isinstance(node, str):
            laid_out.add(node)
        elif isinstance(node, dict):
            walk(node["first"])
            walk(node["second"])

    for tab in config[doc["layout"]]["tabs"]:
        walk(tab["layout"])
    assert laid_out == {k for k in config if k != doc["layout"]}
    return len(paths)


def check_plotjuggler(root: ET.Element, bag: Bag) -> int:
    """Every curve of a PlotJuggler layout is a recorded series or a custom math series
    whose sources are; returns the number of curves."""
    joint_state_topics = {t for t, r in bag.root.items() if r == TYPE_JOINT_STATE}

    def check_series(name: str) -> None:
        topic, parts = bag.topic_of(name, "/")
        if topic in joint_state_topics:  # PlotJuggler: /joint_states/<joint>/<field>
            joint, leaf = parts
            assert joint in bag.joints, name
            bag.check_fields(topic, [f"{leaf}[0]"])
        else:
            bag.check_fields(topic, parts)

    custom = {}
    for snippet in root.iter("snippet"):
        assert snippet.findtext("function", "").strip() == "return value - v1", snippet
        check_series(snippet.findtext("linked_source", "").strip())
        (v1,) = snippet.find("additional_sources") or []
        assert v1.tag == "v1"
        check_series((v1.text or "").strip())
        custom[snippet.get("name", "")] = snippet
    names = [c.get("name", "") for c in root.iter("curve")]
    for name in names:
        if name not in custom:
            check_series(name)
    return len(names)


def _shipped_foxglove() -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((SHIPPED / layouts.FOXGLOVE_FILE).read_text("utf-8"))
    return doc


def test_every_foxglove_path_and_script_field_exists_in_a_recorded_bag(bag: Bag) -> None:
    # seven curves per joint: three positions, two errors, two efforts
    assert check_foxglove(_shipped_foxglove(), bag) == 6 * 7


def test_every_plotjuggler_curve_and_math_source_exists_in_a_recorded_bag(bag: Bag) -> None:
    root = ET.parse(SHIPPED / layouts.PLOTJUGGLER_FILE).getroot()
    assert check_plotjuggler(root, bag) == 6 * 7
    assert len(list(root.iter("snippet"))) == 6


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ('export const inputs = ["/controller_state"', 'export const inputs = ["/controller_stat"'),
        ("event.message.reference.positions", "event.message.reference.position"),
        ("event.message.position,", "event.message.velocities,"),
        ("/foxglove_script/true_state_error.error[0]", "/foxglove_script/true_state_error.err[0]"),
        ("/ground_truth/joint_states.position[0]", "/ground_truth/joint_state.position[0]"),
        ('"followTf": "tool0"', '"followTf": "tool9"'),
        ("/robot_description", "/robot_descriptions"),
    ],
)
def test_a_wrong_name_in_the_foxglove_layout_fails_the_check(bag: Bag, old: str, new: str) -> None:
    def replaced(node: Any) -> Any:
        if isinstance(node, dict):
            return {replaced(k): replaced(v) for k, v in node.items()}
        if isinstance(node, list):
            return [replaced(v) for v in node]
        return node.replace(old, new) if isinstance(node, str) else node

    doc = _shipped_foxglove()
    broken = replaced(doc)
    if old.startswith('"followTf"'):
        broken["configById"][layouts.THREE_D_PANEL]["followTf"] = "tool9"
    else:
        assert broken != doc, old
    with pytest.raises(AssertionError):
        check_foxglove(broken, bag)


@pytest.mark.parametrize(
    ("old", "new"),
    [
        ("<v1>/ground_truth/joint_states/elbow_joint/", "<v1>/ground_truth/joint_states/elbow/"),
        ("<linked_source>/controller_state/reference/positions[1]", "<linked_source>/cs[1]"),
        ('<curve name="true_state_error/wrist_1_joint"', '<curve name="true_error/wrist_1_joint"'),
    ],
)
def test_a_wrong_name_in_the_plotjuggler_layout_fails_the_check(
    bag: Bag, old: str, new: str
) -> None:
    text = (SHIPPED / layouts.PLOTJUGGLER_FILE).read_text(encoding="utf-8")
    assert old in text, old
    with pytest.raises(AssertionError):
        check_plotjuggler(ET.fromstring(text.replace(old, new)), bag)
