"""Provenance of a recording: which code made it (``RECORD_CODE``, :func:`git_commit`)."""

from __future__ import annotations

import subprocess
from pathlib import Path

# The code a recording depends on (relative to pipeline/): the record command's import
# closure, which `make sync` writes here and as dvc.yaml's record deps (pipeline/devtools/
# sync.py; a test fails when they are stale). Recordings carry the last commit that
# changed them, so a commit that only touches the report, docs or results leaves the
# recordings' bytes, and committed results, reproducible from a clone.
RECORD_CODE = (
    # begin generated: record code (make sync)
    "__init__.py",
    "__main__.py",
    "analysis/__init__.py",
    "analysis/catalog.py",
    "analysis/checks.py",
    "analysis/episodes.py",
    "analysis/measure.py",
    "analysis/metrics.py",
    "analysis/protocol.py",
    "analysis/task_space.py",
    "argv.py",
    "cli",
    "constants.py",
    "contract.py",
    "control",
    "errors.py",
    "experiment",
    "fsutil.py",
    "identify/__init__.py",
    "identify/defaults.py",
    "identify/identity.py",
    "identify/model_file.py",
    "kinematics/__init__.py",
    "kinematics/analytic.py",
    "kinematics/fk.py",
    "kinematics/ik.py",
    "kinematics/jacobian.py",
    "kinematics/limits.py",
    "kinematics/numeric.py",
    "kinematics/seeds.py",
    "kinematics/solvers.py",
    "knobs.py",
    "log/__init__.py",
    "log/bag.py",
    "log/cdr.py",
    "log/collect.py",
    "log/db3.py",
    "log/decode.py",
    "log/gather.py",
    "log/labels.py",
    "log/mcap.py",
    "log/msgdef.py",
    "log/notes.py",
    "log/pairing.py",
    "log/reader.py",
    "log/recording.py",
    "log/robot_facts.py",
    "log/rosbag2.py",
    "log/schemas.py",
    "log/streams.py",
    "log/topics.py",
    "log/windowed.py",
    "memory.py",
    "model",
    "params.py",
    "planning/__init__.py",
    "planning/batch.py",
    "planning/collision.py",
    "planning/planner.py",
    "planning/shortcut.py",
    "planning/timing.py",
    "plugins.py",
    "robots/__init__.py",
    "robots/arm3_example.yaml",
    "robots/caps.py",
    "robots/chain.py",
    "robots/dh_yaml.py",
    "robots/facts.py",
    "robots/link_facts.py",
    "robots/link_geometry.py",
    "robots/loaders.py",
    "robots/mdh_example.yaml",
    "robots/mjcf_loader.py",
    "robots/packages.py",
    "robots/panda.armlab.yaml",
    "robots/panda_dh.yaml",
    "robots/recorded.py",
    "robots/sidecar.py",
    "robots/spec.py",
    "robots/srdf.py",
    "robots/ur10.yaml",
    "robots/ur5.yaml",
    "robots/urdf.py",
    "robots/urdf_loader.py",
    "settings.py",
    "sim/__init__.py",
    "sim/contact_gate.py",
    "sim/loop.py",
    "sim/plant.py",
    "sim/result.py",
    "sim/runner.py",
    "sim/safety.py",
    "sim/settling.py",
    "stages/__init__.py",
    "stages/budget.py",
    "stages/campaign_expand.py",
    "stages/campaign_record.py",
    "stages/campaign_run.py",
    "stages/episode.py",
    "stages/executors",
    "stages/plans.py",
    "stages/provenance.py",
    "stages/record.py",
    "stages/workers.py",
    "supervise.py",
    "trajectory.py",
    "transforms.py",
    "yamlio.py",
    # end generated: record code
)


def git_commit(paths: tuple[str, ...] = RECORD_CODE) -> str:
    """Last commit that changed the record code (or ``paths``, relative to pipeline/),
    ``-dirty`` if it has local changes.

    "" outside a git checkout.
    """
    package = Path(__file__).resolve().parents[1]

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=package, capture_output=True, text=True, check=True
        ).stdout.strip()

    try:
        sha = git("log", "-1", "--format=%H", "--", *paths)
        dirty = git("status", "--porcelain", "--untracked-files=no", "--", *paths)
    except (OSError, subprocess.CalledProcessError):
        return ""
    return f"{sha}-dirty" if sha and dirty else sha
