"""Hostile robot files end in one line naming the file and what was wrong, before any
engine sees them: unreadable meshes, meshes outside the robot's folder, and the stated caps
of :mod:`pipeline.robots.caps` (joints, nesting, mimic chains, magnitudes)."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from pipeline.errors import SpecError
from pipeline.robots import load_spec
from pipeline.robots.caps import MAX_MESH_BYTES
from tests.robots.test_mjcf_loader import ONE_HINGE
from tests.robots.test_urdf_loader import THREE_JOINT

SPHERE = '<sphere radius="0.03"/>'


def _refused(path: Path, says: str) -> None:
    with pytest.raises(SpecError) as err:
        load_spec(path)
    message = str(err.value)
    assert "\n" not in message and str(path) in message, message
    assert says in message, message


def _with_mesh(tmp_path: Path, filename: str) -> Path:
    urdf = tmp_path / "robot" / "arm.urdf"
    urdf.parent.mkdir(exist_ok=True)
    urdf.write_text(THREE_JOINT.replace(SPHERE, f'<mesh filename="{filename}"/>'))
    return urdf


def _binary_stl(triangles: np.ndarray, claimed: int | None = None) -> bytes:
    n = len(triangles)
    out = b"\0" * 80 + struct.pack("<I", n if claimed is None else claimed)
    for tri in triangles:
        out += struct.pack("<12f", 0, 0, 1, *tri.ravel()) + b"\0\0"
    return out


TRI = np.array([[[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]]], dtype=float)
MESHES: dict[str, tuple[bytes, str]] = {
    "empty.obj": (b"", "empty file"),
    "faceless.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    "malformed.obj": (b"v 0 0 0\nv 1 zero 0\nf 1 2 3\n", "line 2: malformed vertex"),
    "bad-index.obj": (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "line 4: malformed face"),
    "nan.obj": (b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n", "line 2: non-finite vertex"),
    "random.stl": (np.random.default_rng(0).bytes(1000), "not an STL"),
    "claims-4e9.stl": (b"\0" * 80 + struct.pack("<I", 4_000_000_000), "not an STL"),
    "nan.stl": (_binary_stl(TRI * np.nan), "non-finite vertex"),
    "text.stl": (b"root:x:0:0:root:/root:/bin/bash\n", "not an STL"),
}


@pytest.mark.parametrize("name", list(MESHES))
def test_a_mesh_mujoco_cannot_read_is_named_before_mujoco_sees_it(tmp_path, name):
    data, says = MESHES[name]
    urdf = _with_mesh(tmp_path, name)
    (urdf.parent / name).write_bytes(data)
    _refused(urdf, f"{urdf.parent / name}: {says}")


def test_a_readable_mesh_still_loads(tmp_path):
    urdf = _with_mesh(tmp_path, "ok.stl")
    (urdf.parent / "ok.stl").write_bytes(_binary_stl(TRI))
    assert load_spec(urdf).joints[2].shapes[0].kind == "mesh"


def test_a_mesh_over_the_size_cap_is_refused_without_reading_it(tmp_path):
    urdf = _with_mesh(tmp_path, "huge.stl")
    with open(urdf.parent / "huge.stl", "wb") as f:
        f.truncate(500 * 2**20)  # sparse: 500 MB claimed, nothing on disk
    _refused(urdf, f"more than the cap of {MAX_MESH_BYTES} bytes")


def test_a_mesh_path_leaving_the_package_is_refused(tmp_path, monkeypatch):
    (tmp_path / "share" / "pkg").mkdir(parents=True)
    (tmp_path / "secret.stl").write_bytes(_binary_stl(TRI))
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "share"))
    _refused(_with_mesh(tmp_path, "package://pkg/../../secret.stl"), "leaves the package 'pkg'")


@pytest.mark.parametrize("how", ["absolute", "file://", "relative"])
def test_a_mesh_path_outside_the_robot_folder_is_refused(tmp_path, how):
    outside = tmp_path / "elsewhere" / "passwd.stl"
    outside.parent.mkdir()
    outside.write_bytes(_binary_stl(TRI))
    filename = {"absolute": str(outside), "file://": f"file://{outside}",
                "relative": "../elsewhere/passwd.stl"}[how]  # fmt: skip
    _refused(_with_mesh(tmp_path, filename), "outside the robot's folder")


def test_a_ros_package_layout_may_reach_its_meshes_folder(tmp_path):
    urdf = tmp_path / "pkg" / "urdf" / "arm.urdf"
    (tmp_path / "pkg" / "meshes").mkdir(parents=True)
    urdf.parent.mkdir()
    (tmp_path / "pkg" / "meshes" / "l3.stl").write_bytes(_binary_stl(TRI))
    urdf.write_text(THREE_JOINT.replace(SPHERE, '<mesh filename="../meshes/l3.stl"/>'))
    assert load_spec(urdf).dof == 3


def _chain(n: int) -> str:
    links = "".join(f'<link name="l{i}"/>' for i in range(n + 1))
    joints = "".join(
        f'<joint name="j{i}" type="revolute"><parent link="l{i}"/><child link="l{i + 1}"/>'
        '<limit lower="-1" upper="1" velocity="1" effort="1"/></joint>'
        for i in range(n)
    )
    return f'<robot name="long">{links}{joints}</robot>'


CASES: dict[str, tuple[str, str]] = {
    "mass-1e-12": (THREE_JOINT.replace('<mass value="0.8"/>', '<mass value="1e-12"/>'),
                   "mass 1e-12 kg is out of range"),
    "mass-1e9": (THREE_JOINT.replace('<mass value="0.8"/>', '<mass value="1e9"/>'),
                 "mass 1e+09 kg is out of range"),
    "limit-1e308": (THREE_JOINT.replace('lower="-3" upper="3"', 'lower="-1e308" upper="1e308"'),
                    "joint 'j1'.limit.lower: -1e+308 is out of range"),
    "origin-1e300": (THREE_JOINT.replace('<origin xyz="0.3 0 0"', '<origin xyz="1e300 0 0"'),
                     "joint 'j3'.origin.xyz: '1e300 0 0' is out of range"),
    "inertial-origin": (THREE_JOINT.replace('<origin xyz="0.1 0 0"/>', '<origin xyz="0 0 1e5"/>'),
                        "link 'l3'.origin.xyz"),
    "duplicate-link": (THREE_JOINT.replace('<link name="tool0"/>', '<link name="l3"/>'),
                       "duplicate link name 'l3'"),
    "mimic-cycle": (THREE_JOINT.replace(
        '<joint name="tool_joint"',
        '<link name="fa"/><link name="fb"/>'
        '<joint name="a" type="revolute"><parent link="l3"/><child link="fa"/><mimic joint="b"/>'
        '<limit lower="-1" upper="1" velocity="1" effort="1"/></joint>'
        '<joint name="b" type="revolute"><parent link="l3"/><child link="fb"/><mimic joint="a"/>'
        '<limit lower="-1" upper="1" velocity="1" effort="1"/></joint>'
        '<joint name="tool_joint"'), "mimic cycle: a -> b -> a"),
    "1000-joints": (_chain(1000), "1001 links, more than the cap of 512"),
    "100-joints": (_chain(100), "100 movable joints, more than the cap of 64"),
    "deep-nesting": (THREE_JOINT.replace("</robot>", "<a>" * 10_000 + "</a>" * 10_000
                                         + "</robot>"), "nested more than 32 deep"),
    "bad-name": (THREE_JOINT.replace('name="j2"', 'name="j 2"'), "joint name 'j 2'"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(CASES))
def test_a_urdf_past_a_stated_cap_is_one_line(tmp_path, case):
    text, says = CASES[case]
    path = tmp_path / f"{case}.urdf"
    path.write_text(text)
    _refused(path, says)


def test_an_srdf_named_state_holding_nan_is_refused(tmp_path):
    (tmp_path / "three.urdf").write_text(THREE_JOINT)
    (tmp_path / "three.srdf").write_text(
        '<robot name="three"><group_state name="ready" group="arm"><joint name="j1" value="0"/>'
        '<joint name="j2" value="nan"/><joint name="j3" value="0"/></group_state></robot>'
    )
    says = r"three.srdf: group_state 'ready': joint 'j2': value 'nan'"
    with pytest.raises(SpecError, match=says):
        load_spec(tmp_path / "three.urdf")


def _mjcf_chain(n: int) -> str:
    body = '<geom size="0.02" mass="0.1"/>'
    for i in reversed(range(n)):
        joint = f'<joint name="j{i}" range="-1 1" actuatorfrcrange="-1 1"/>'
        geom = '<geom size="0.02" mass="0.1"/>'
        body = f'<body name="b{i}" pos="0 0 0.01">{joint}{geom}{body}</body>'
    return f'<mujoco model="long"><worldbody>{body}</worldbody></mujoco>'


MJCF_CASES: dict[str, tuple[str, str]] = {
    "range-reversed": (ONE_HINGE.replace('name="j2" axis="0 1 0" range="-2 2"',
                                         'name="j2" axis="0 1 0" range="2 1"'),
                       "joint 'j2': range lower 2 is above upper 1"),
    "pos-1e300": (ONE_HINGE.replace('pos="0 0 0.2"', 'pos="0 0 1e300"'), "body 'l2': pos"),
    "mass-1e-12": (ONE_HINGE.replace('mass="0.5"', 'mass="1e-12"'),
                   "body 'l2': mass 1e-12 kg is out of range"),
    "100-joints": (_mjcf_chain(100), "100 joints, more than the cap of 64"),
    "mesh-random": (ONE_HINGE.replace("<worldbody>", '<asset><mesh name="m" file="m.stl"/>'
                                      "</asset><worldbody>"), "mesh 'm': mesh"),
    "model-name": (ONE_HINGE.replace('model="arm"', 'model="my arm"'), "robot name 'my arm'"),
}  # fmt: skip


@pytest.mark.parametrize("case", list(MJCF_CASES))
def test_an_mjcf_past_a_stated_cap_is_one_line(tmp_path, case):
    text, says = MJCF_CASES[case]
    path = tmp_path / f"{case}.xml"
    path.write_text(text)
    (tmp_path / "m.stl").write_bytes(np.random.default_rng(1).bytes(999))
    _refused(path, says)
