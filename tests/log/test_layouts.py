"""The Foxglove and PlotJuggler layouts we ship open our bags: every topic and field path
they name exists in a bag `pipeline record` writes."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from pipeline.constants import TOPIC_JOINT_STATES, TYPE_JOINT_STATE
from pipeline.log import layouts
from pipeline.log.msgdef import MsgTypes, parse_msgdef, root_type_name
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

    def topic_of(self, path: str, sep: str) -> tuple[str, list[str]]:
        """The longest recorded topic ``path`` starts with, and the rest split at ``sep``."""
        topics = [t for t in self.types if path.startswith(t + sep)]
        assert topics, f"{path}: no recorded topic (recorded: {sorted(self.types)})"
        topic = max(topics, key=len)
        return topic, path[len(topic) + 1 :].split(sep)

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
            assert curve.topic in ours, curve


def test_every_foxglove_path_exists_in_a_recorded_bag(bag: Bag) -> None:
    doc = json.loads((SHIPPED / layouts.FOXGLOVE_FILE).read_text(encoding="utf-8"))
    config = doc["configById"]
    paths = [p["value"] for panel in config.values() for p in panel.get("paths", [])]
    assert len(paths) == 6 * 6  # six curves per joint
    for path in paths:
        topic, parts = bag.topic_of(path, ".")
        bag.check_fields(topic, parts)
    # every panel the tabs lay out is configured, and every configured plot is laid out
    laid_out: set[str] = set()

    def walk(node: object) -> None:
        if isinstance(node, str):
            laid_out.add(node)
        elif isinstance(node, dict):
            walk(node["first"])
            walk(node["second"])

    for tab in config[doc["layout"]]["tabs"]:
        walk(tab["layout"])
    assert laid_out == {k for k in config if k.startswith("Plot!")}


def test_every_plotjuggler_curve_exists_in_a_recorded_bag(bag: Bag) -> None:
    root = ET.parse(SHIPPED / layouts.PLOTJUGGLER_FILE).getroot()
    names = [c.get("name", "") for c in root.iter("curve")]
    assert len(names) == 6 * 6
    joint_state_topics = {t for t, r in bag.root.items() if r == TYPE_JOINT_STATE}
    for name in names:
        topic, parts = bag.topic_of(name, "/")
        if topic in joint_state_topics:  # PlotJuggler: /joint_states/<joint>/<field>
            joint, leaf = parts
            assert joint in bag.joints, name
            bag.check_fields(topic, [f"{leaf}[0]"])
        else:
            bag.check_fields(topic, parts)
