"""A hostile or malformed URDF on a foreign bag's /robot_description: named as malformed in
one note, dropped (nothing downstream parses it again), and the rest of the bag read."""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from rosbags.rosbag2 import StoragePlugin

from pipeline.log.labels import URDF_MAX_CHARS, urdf_problem
from pipeline.log.reader import read_recording
from pipeline.stages.report import run_report
from tests.log.test_external_bags import JOINTS, N, write_external_bag

JOINT = (
    '<joint name="{j}" type="revolute">'
    '<limit effort="{e}" velocity="3" lower="-3" upper="3"/></joint>'
)
GOOD = "".join(JOINT.format(j=j, e=40) for j in JOINTS)
LAUGHS = (
    '<?xml version="1.0"?><!DOCTYPE robot [<!ENTITY a0 "lol">'
    + "".join(f'<!ENTITY a{i} "{f"&a{i - 1};" * 10}">' for i in range(1, 10))
    + ']><robot name="&a9;"/>'
)
HOSTILE = {
    "not-xml": ("this is not <xml", "not XML"),
    "billion-laughs": (LAUGHS, "entities"),
    "huge": (
        '<robot name="big">' + GOOD + "<!--" + "x" * (URDF_MAX_CHARS + 1) + "--></robot>",
        "characters",
    ),
    "deep": ('<robot name="deep">' + GOOD + "<a>" * 10_000 + "</a>" * 10_000 + "</robot>", "deep"),
    "not-a-robot": ("<sdf/>", "expected <robot>"),
    "effort-nan": (f'<robot name="r">{JOINT.format(j="shoulder", e="nan")}</robot>', "'nan'"),
    "effort-negative": (f'<robot name="r">{JOINT.format(j="elbow", e="-5")}</robot>', "'-5'"),
    "effort-word": (
        f'<robot name="r">{JOINT.format(j="elbow", e="strong")}</robot>',
        "not a number",
    ),
    "lower-above-upper": (
        '<robot name="r"><joint name="w"><limit effort="1" velocity="1" lower="2" upper="1"/>'
        "</joint></robot>",
        "above upper",
    ),
    "mass-inf": (
        '<robot name="r"><link name="l"><inertial><mass value="inf"/></inertial></link></robot>',
        "'inf'",
    ),
}


@pytest.mark.parametrize("case", list(HOSTILE))
def test_a_hostile_urdf_is_named_malformed_and_the_bag_still_reads(
    tmp_path: Path, case: str
) -> None:
    text, why = HOSTILE[case]
    path = tmp_path / case
    write_external_bag(path, distro="jazzy", storage=StoragePlugin.MCAP, urdf=text)
    started = time.perf_counter()
    rec = read_recording(path)
    assert time.perf_counter() - started < 30
    assert rec.robot_description is None  # dropped: no later parser sees it
    [note] = [n for n in rec.notes if "malformed URDF" in n]
    assert why in note and "\n" not in note and len(note) < 400
    assert not any("effort limits from the bag" in n for n in rec.notes)
    assert rec.robot == "n/a"
    assert rec.samples["stamp_ns"].n_unique() == N  # the rest of the bag is there


def test_a_good_urdf_has_no_problem() -> None:
    assert urdf_problem(f'<?xml version="1.0"?><robot name="r">{GOOD}</robot>') is None


def test_the_report_runs_on_a_bag_with_an_entity_bomb(tmp_path: Path) -> None:
    bags = tmp_path / "bags"
    write_external_bag(bags / "bomb", distro="jazzy", storage=StoragePlugin.MCAP, urdf=LAUGHS)
    result = run_report(recordings_dir=bags, out_dir=tmp_path / "out", baseline="bomb")
    assert result.summary.height == 1
    assert any("malformed URDF" in note for _, note in result.warnings)
