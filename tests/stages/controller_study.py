"""A two-controller study on the UR5 (short episodes, seeds per controller) as a params file,
the CLI run in a subprocess, and a recorded bag's settings: one copy for the tests that
record the same law on two nominals or two plants and compare them by seed."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import yaml


def params_file(
    folder: Path,
    *,
    controllers: dict[str, dict[str, Any]],
    seeds: dict[str, tuple[int, ...]],
    scenario_extra: dict[str, Any] | None = None,
) -> Path:
    """Write ``folder/params.yaml``: one UR5 scenario (0.1 s preroll and hold, plus
    ``scenario_extra``), ``controllers``, and an episode ``<controller>-<seed>`` for each
    controller's seeds; returns its path."""
    scenario = {
        "robot": "ur5",
        "start": [0.0] * 6,
        "goal": {"joints": [-0.15, -0.5, 0.785, -1.15, -0.3925, 0.0]},
        "planner": {"time_limit_s": 5.0, "simplify": True, "seed": 0},
        **(scenario_extra or {}),
        "preroll_s": 0.1,
        "hold_s": 0.1,
    }
    params = {
        "sim": {"physics_dt_s": 0.002, "control_period_steps": 1, "integrator": "Euler"},
        "scenarios": {"s": scenario},
        "controllers": controllers,
        "episodes": {
            f"{c}-{seed}": {"scenario": "s", "controller": c, "seed": seed}
            for c in controllers
            for seed in seeds[c]
        },
    }
    path = folder / "params.yaml"
    path.write_text(yaml.safe_dump(params))
    return path


def cli(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """``python -m pipeline *argv`` in ``cwd``, output captured."""
    return subprocess.run(
        [sys.executable, "-m", "pipeline", *argv],
        capture_output=True, text=True, timeout=600, check=False, cwd=cwd,
    )  # fmt: skip


def settings_of(bag_dir: Path) -> dict[str, Any]:
    """The episode settings (JSON) a recorded bag's metadata.yaml carries."""
    meta = yaml.safe_load((bag_dir / "metadata.yaml").read_text())
    found: list[dict[str, Any]] = []

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                if key == "settings" and isinstance(value, str):
                    found.append(json.loads(value))
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(meta)
    assert found, f"no settings in {bag_dir}/metadata.yaml"
    return found[0]
