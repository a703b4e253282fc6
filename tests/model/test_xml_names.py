"""Names reach URDF and MJCF intact: the loader refuses what XML cannot carry, the
writers escape what it can.

The escaping is checked by building a spec past the loader (its names hold every XML
special character) and reading the generated XML back with three independent parsers:
ElementTree, MuJoCo and Pinocchio.
"""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from importlib import resources

import mujoco
import pytest
import yaml

from pipeline.errors import SpecError
from pipeline.model.mjcf import Box, build_mjcf, build_mujoco_model
from pipeline.robots import load_spec
from pipeline.robots.chain import link_name
from pipeline.robots.dh_yaml import parse_spec
from pipeline.robots.urdf import build_pinocchio_model, build_urdf

NASTY = ['a"b', "c<d>", "e&f", "g'h", "i&amp;j", "k l", "m\tn"]


def _renamed(names: list[str]):
    ur5 = load_spec("ur5")
    joints = tuple(
        dataclasses.replace(j, name=n) for j, n in zip(ur5.joints, [*names, "w3"], strict=False)
    )
    return dataclasses.replace(ur5, name='ur5 "<&>"', joints=joints)


def test_urdf_carries_names_with_xml_special_characters_verbatim():
    spec = _renamed(NASTY[:5])
    root = ET.fromstring(build_urdf(spec))
    assert root.get("name") == spec.name
    revolute = [j for j in root.iter("joint") if j.get("type") == "revolute"]
    assert [j.get("name") for j in revolute] == list(spec.joint_names)
    assert [j.find("child").get("link") for j in revolute] == [
        link_name(n) for n in spec.joint_names
    ]
    model = build_pinocchio_model(spec)
    assert list(model.names)[1:] == list(spec.joint_names)


def test_mjcf_carries_names_with_xml_special_characters_verbatim():
    spec = _renamed(NASTY[:5])
    obstacle = Box('box "&" <1>', (1.0, 1.0, 1.0), (0.1, 0.1, 0.1))
    ET.fromstring(build_mjcf(spec, obstacles=[obstacle]))
    model = build_mujoco_model(spec, obstacles=[obstacle])
    names = [model.joint(i).name for i in range(model.njnt)]
    assert names == list(spec.joint_names)
    assert model.geom(obstacle.name).type == mujoco.mjtGeom.mjGEOM_BOX
    assert model.body(link_name(spec.joint_names[0])).id > 0


@pytest.mark.parametrize("name", [*NASTY, "a\x00b", "/ns/joint", "1joint", "", "j" * 101])
def test_the_loader_refuses_names_outside_the_rule_in_one_line(name):
    data = yaml.safe_load((resources.files("pipeline.robots") / "ur5.yaml").read_text())
    data["joints"][2]["name"] = name
    with pytest.raises(SpecError) as err:
        parse_spec(data, source="arm.yaml")
    message = str(err.value)
    assert message.startswith("arm.yaml: joints[2].name: invalid name: a name starts with")
    assert "\n" not in message


@pytest.mark.parametrize("name", ["elbow_joint", "_j2", "Joint-2.b", "j" * 100])
def test_the_loader_accepts_ros_style_names(name):
    data = yaml.safe_load((resources.files("pipeline.robots") / "ur5.yaml").read_text())
    data["joints"][2]["name"] = name
    assert parse_spec(data, source="arm.yaml").joint_names[2] == name
