"""Provenance of a recording: which code made it (``RECORD_CODE``, :func:`git_commit`)."""

from __future__ import annotations

import subprocess
from pathlib import Path

# The code a recording depends on (relative to pipeline/): dvc.yaml's record deps list
# the same paths (a test keeps them equal), and recordings carry the last commit that
# changed them, so a commit that only touches the report, docs or results leaves the
# recordings' bytes, and committed results, reproducible from a clone.
RECORD_CODE = (
    "__init__.py",
    "__main__.py",
    "cli",
    "constants.py",
    "contract.py",
    "errors.py",
    "fsutil.py",
    "knobs.py",
    "memory.py",
    "params.py",
    "plugins.py",
    "settings.py",
    "trajectory.py",
    "yamlio.py",
    "identify/__init__.py",  # cli's sub-app, and a scenario's `nominal:` model file
    "identify/cli.py",
    "identify/defaults.py",
    "identify/identity.py",
    "identify/model_file.py",
    "robots",
    "model",
    "kinematics",
    "planning",
    "control",
    "sim",
    "log/__init__.py",
    "log/bag.py",
    "log/cdr.py",
    "log/gather.py",
    "log/mcap.py",
    "log/msgdef.py",
    "log/rosbag2.py",
    "log/schemas.py",
    "log/topics.py",
    "stages/__init__.py",
    "stages/assemble.py",
    "stages/budget.py",
    "stages/campaign.py",
    "stages/campaign_run.py",
    "stages/episode.py",
    "stages/executors",
    "stages/goals.py",
    "stages/plans.py",
    "stages/provenance.py",
    "stages/record.py",
    "stages/workers.py",
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
