"""example-robot-data arms nobody here prepared load as a user would give them (the URDF,
a one-line sidecar naming the tip where there are several leaf chains) and our forward
kinematics equals an independent URDF reader's (yourdfpy) at random poses.

Each was refused or wrong at first contact before issue 31's last stop: SO-101 (a frame
link's placeholder mass; a tip that is a frame), TIAGo (an antenna's inertial that is no
rigid body's, on the base), Baxter (a fixed joint's and the head's absurd limits)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from pipeline.robots import load_spec
from tests.robots.panda_files import ERD, assert_fk_matches_yourdfpy, needs_erd

pytestmark = needs_erd

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
    assert ERD is not None
    path = tmp_path / Path(urdf).name  # beside its sidecar, as a user's copy would be
    shutil.copy(ERD / "robots" / urdf, path)
    if tip is not None:
        path.with_name(f"{path.stem}.armlab.yaml").write_text(f"tip: {tip}\n")
    spec = load_spec(path)
    assert spec.dof == dof
    end = tip or spec.joints[-1].link_name
    assert_fk_matches_yourdfpy(spec, path, end, seed=3, poses=5, atol=1e-9)
