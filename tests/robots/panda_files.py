"""example-robot-data's Panda as files in a test's folder: its URDF copied out (with or
without its meshes) and the MJCF MuJoCo makes of it. One copy of each recipe, for every
test that needs a Panda robot file of its own."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from pipeline.model.dh import forward_kinematics
from pipeline.robots.packages import package_search_path
from pipeline.robots.spec import RobotSpec

ERD = next((p / "example-robot-data" for p in package_search_path()
            if (p / "example-robot-data").is_dir()), None)  # fmt: skip
needs_erd = pytest.mark.skipif(ERD is None, reason="example-robot-data is not installed")


def assert_fk_matches_yourdfpy(
    spec: RobotSpec, urdf: Path | str, frame: str, *, seed: int, poses: int, atol: float
) -> None:
    """Our forward kinematics of ``spec`` equals yourdfpy's transform from the base to
    ``frame`` of ``urdf`` at ``poses`` uniform random configurations (locked joints at 0)."""
    robot: Any = yourdfpy_robot(urdf)
    rng = np.random.default_rng(seed)
    for _ in range(poses):
        q = rng.uniform(spec.lower, spec.upper)
        robot.update_cfg(dict(zip(spec.joint_names, q, strict=True)))
        want = robot.get_transform(frame_to=frame, frame_from=spec.base_link)
        np.testing.assert_allclose(forward_kinematics(spec, q), want, atol=atol)


def yourdfpy_robot(urdf: Path | str) -> object:
    """``urdf`` read by yourdfpy (an independent URDF reader; skips the test without it),
    its ``package://`` files resolved in example-robot-data's share, meshes not loaded."""
    yourdfpy = pytest.importorskip("yourdfpy")
    assert ERD is not None
    share = ERD.parent

    def handler(fname: str) -> str:
        return str(share / fname.removeprefix("package://"))

    return yourdfpy.URDF.load(
        str(urdf), load_meshes=False, build_collision_scene_graph=False, filename_handler=handler
    )


# The URDF's place in example-robot-data, and the settings the built-in panda's sidecar
# (pipeline/robots/panda.armlab.yaml) gives it but its SRDF: fingers locked, TCP flange.
PANDA_DESCRIPTION = "robots/panda_description"
PANDA_URDF = f"{PANDA_DESCRIPTION}/urdf/panda.urdf"
PANDA_SIDECAR = "locked: {panda_finger_joint1: 0.0}\nflange: panda_hand_tcp\n"


def copy_panda_urdf(folder: Path, *, meshes: bool = False) -> Path:
    """The Panda URDF copied into ``folder`` (made if absent) with a sidecar naming no SRDF.

    Args:
        folder: where the copy goes.
        meshes: False: ``folder/panda.urdf`` alone, its ``package://`` meshes still the
            installed package's. True: the whole ``panda_description`` copied into
            ``folder`` and its URDF (``folder/urdf/panda.urdf``) pointing at the copy's
            meshes, so deleting ``folder`` deletes every file of the robot.

    Returns:
        the copied URDF.
    """
    assert ERD is not None
    if meshes:
        shutil.copytree(ERD / PANDA_DESCRIPTION, folder)
        urdf = folder / "urdf" / "panda.urdf"
        text = urdf.read_text(encoding="utf-8")
        package = f"package://example-robot-data/{PANDA_DESCRIPTION}/"
        urdf.write_text(re.sub(re.escape(package), "../", text), encoding="utf-8")
    else:
        folder.mkdir(parents=True, exist_ok=True)
        urdf = folder / "panda.urdf"
        shutil.copy(ERD / PANDA_URDF, urdf)
    (urdf.parent / "panda.armlab.yaml").write_text(PANDA_SIDECAR)
    return urdf


def panda_mjcf(folder: Path) -> Path:
    """The Panda URDF through MuJoCo's URDF import, saved as MJCF (``mj_saveLastXML``) in
    ``folder``, with the sidecar facts the built-in panda's URDF gets (its armature:
    Menagerie's).

    Meshes are left out (FK and dynamics need none), the fingers' ``<mimic>`` too (MuJoCo
    would make it an equality constraint); static bodies are kept, so the TCP is a body.
    """
    import mujoco

    assert ERD is not None
    text = (ERD / PANDA_URDF).read_text(encoding="utf-8")
    text = re.sub(r"<(visual|collision)>.*?</\1>", "", text, flags=re.S)
    text = re.sub(r"<mimic[^>]*/>", "", text)
    text = re.sub(r"(<robot[^>]*>)", r'\1<mujoco><compiler fusestatic="false"/></mujoco>', text)
    urdf = folder / "panda.urdf"
    urdf.write_text(text)
    model = mujoco.MjModel.from_xml_path(str(urdf))
    xml = folder / "panda_mjcf.xml"
    mujoco.mj_saveLastXML(str(xml), model)
    (folder / "panda_mjcf.armlab.yaml").write_text(
        "tip: panda_link7\nflange: panda_hand_tcp\narmature: 0.1\n"
    )
    return xml
