"""Episode facts from settings: tolerant of missing or differently shaped settings."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from pipeline.analysis.episodes import episode_table, robot_spec
from pipeline.log.reader import Recording, read_recording
from pipeline.log.robot_facts import robot_facts
from pipeline.model.dh import forward_kinematics
from pipeline.robots import load_spec
from tests.analysis.bagfactory import default_settings, paper_like, write_bag


def _recording(tmp_path: Path, settings: dict | None, name: str = "ep") -> Recording:
    ep = paper_like(name, "pid", duration_s=0.2, motion_end_s=0.1)
    ep.settings = default_settings(ep) if settings is None else settings
    return read_recording(write_bag(tmp_path, ep))


def test_robot_from_settings_has_the_same_kinematics_as_the_builtin(tmp_path: Path) -> None:
    rec = _recording(tmp_path, None)
    spec = robot_spec(rec)
    assert spec is not None and spec.joint_names == load_spec("ur5").joint_names
    q = np.array([0.1, -0.5, 0.7, -1.0, 0.3, 0.2])
    np.testing.assert_allclose(forward_kinematics(spec, q), forward_kinematics(load_spec("ur5"), q))


def test_robot_dumped_as_dataclasses_is_understood_too(tmp_path: Path) -> None:
    ep = paper_like("dc", "pid", duration_s=0.2)
    settings = default_settings(ep)
    settings["robot"] = dataclasses.asdict(load_spec("ur5"))
    rec = _recording(tmp_path, settings, "dc")
    spec = robot_spec(rec)
    assert spec is not None
    assert robot_facts(rec).effort_limits_nm["wrist_3_joint"] == 28.0


def test_missing_settings_fall_back_to_metadata_and_na(tmp_path: Path) -> None:
    rec = _recording(tmp_path, {})
    assert robot_spec(rec) == load_spec("ur5")  # built-in of the recorded robot name
    table = episode_table([rec])
    row = table.row(0, named=True)
    assert (row["controller"], row["scenario"], row["status"]) == ("pid", "paper", "ok")
    assert row["motion_end_s"] == pytest.approx(0.1)  # last planned point
    assert rec.settings is None and not rec.notes  # absent: n/a, nothing to note


def test_a_robot_that_is_not_one_refuses_the_settings_with_a_note(tmp_path: Path) -> None:
    """settings.robot is the robot by value: one that does not parse breaks the contract
    (the settings are n/a, with a note naming the field); the recorded robot name stands."""
    ep = paper_like("raw", "pid", duration_s=0.2)
    settings = default_settings(ep)
    settings["robot"] = {
        "name": "odd",
        "joints": [{"name": "shoulder_pan_joint", "limits": {"effort": 99.0}}],
    }
    rec = _recording(tmp_path, settings, "raw")
    assert rec.settings is None
    assert any("settings.robot: " in n and "settings are n/a" in n for n in rec.notes)
    assert robot_spec(rec) == load_spec("ur5")  # the built-in of the recorded robot name
    assert robot_facts(rec).effort_limits_nm["shoulder_pan_joint"] == 150.0


def test_a_foreign_bag_gives_no_settings_and_its_own_urdf_facts(tmp_path: Path) -> None:
    ep = paper_like("foreign", "jtc", duration_s=0.2)
    ep.episode_metadata = False  # a bag we did not write (and without a URDF)
    rec = read_recording(write_bag(tmp_path, ep))
    assert rec.settings is None and not rec.armlab_metadata
    assert any("no 'armlab.episode' metadata record" in n for n in rec.notes)
    facts = robot_facts(rec)
    assert (facts.name, facts.source, facts.spec) == (rec.robot, "urdf", None)
    assert facts.effort_limits_nm == dict.fromkeys(rec.joint_names)  # unknown: no URDF
