"""example-robot-data arms nobody here prepared load as a user would give them (the URDF,
a one-line sidecar naming the tip where there are several leaf chains) and our forward
kinematics equals an independent URDF reader's (yourdfpy) at random poses.

Each was refused or wrong at first contact before issue 31's last stop: SO-101 (a frame
link's placeholder mass; a tip that is a frame), TIAGo (an antenna's inertial that is no
rigid body's, on the base), Baxter (a fixed joint's and the head's absurd limits)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from pipeline.model.dh import forward_kinematics
from pipeline.robots import load_spec
from pipeline.robots.packages import package_search_path

SHARE = next(
    (p / "example-robot-data" / "robots" for p in package_search_path() if
     (p / "example-robot-data").is_dir()),
    None,
)  # fmt: skip
pytestmark = pytest.mark.skipif(SHARE is None, reason="example-robot-data share not found")

ARMS = [
    # (URDF under the share, tip: for the sidecar (None: the single leaf chain), joints)
    ("so_arm_description/urdf/so101.urdf", "gripper_frame_link", 5),
    ("z1_description/urdf/z1.urdf", None, 7),
    ("xarm_description/urdf/xarm7.urdf", None, 7),
    ("kinova_description/robots/kinova.urdf", None, 6),
    ("tiago_description/robots/tiago.urdf", "arm_7_link", 8),
    ("baxter_description/urdf/baxter.urdf", "right_wrist", 7),
]


@pytest.mark.parametrize(("urdf", "tip", "dof"), ARMS, ids=[Path(a[0]).stem for a in ARMS])
def test_an_example_robot_data_arm_loads_and_agrees_with_yourdfpy(
    tmp_path: Path, urdf: str, tip: str | None, dof: int
) -> None:
    yourdfpy = pytest.importorskip("yourdfpy")
    assert SHARE is not None
    path = tmp_path / Path(urdf).name  # beside its sidecar, as a user's copy would be
    shutil.copy(SHARE / urdf, path)
    if tip is not None:
        path.with_name(f"{path.stem}.armlab.yaml").write_text(f"tip: {tip}\n")
    spec = load_spec(path)
    assert spec.dof == dof
    share = SHARE.parent.parent

    def handler(fname: str) -> str:
        return str(share / fname.removeprefix("package://"))

    robot = yourdfpy.URDF.load(
        str(path), load_meshes=False, build_collision_scene_graph=False, filename_handler=handler
    )
    end = tip or spec.joints[-1].link_name
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(spec.lower, spec.upper)
        robot.update_cfg(dict(zip(spec.joint_names, q, strict=True)))
        want = robot.get_transform(frame_to=end, frame_from=spec.base_link)
        np.testing.assert_allclose(forward_kinematics(spec, q), want, atol=1e-9)
