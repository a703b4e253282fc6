"""Record-stage memory and time per control step: the basis of the resource estimate.

Runs ``pipeline record`` on the paper's CTC episode (UR5, 1 kHz, full logging) with
growing ``hold_s``, each in a fresh process, and fits peak RSS and wall time against
the number of control steps. The slopes, divided by the 6 joints, are what
``pipeline.stages.budget`` assumes (``BYTES_PER_JOINT_STEP``, ``SECONDS_PER_JOINT_STEP``);
it prints both so a change in the logging shows up as a gap.

Usage: python benches/record_memory.py [--holds 1 11 31 61]
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.stages import budget  # noqa: E402

# Peak RSS of the child, read by a parent whose only child it is.
_WRAPPER = (
    "import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, "
    "stdout=subprocess.DEVNULL); print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)"
)


def peak_rss_bytes(params: Path, out: Path) -> tuple[int, float]:
    """Peak RSS [B] and wall time [s] of one `pipeline record --only paper-ctc` run."""
    t0 = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-c", _WRAPPER, sys.executable, "-m", "pipeline", "record",
         "--params", str(params), "--out", str(out), "--only", "paper-ctc", "--force"],
        cwd=REPO, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return int(result.stdout.split()[-1]) * 1024, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--holds", type=float, nargs="+", default=[1.0, 11.0, 31.0, 61.0])
    args = parser.parse_args()
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    steps, rss, wall = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for hold in args.holds:
            data["scenarios"]["paper"]["hold_s"] = hold
            params = Path(tmp) / f"p{hold}.yaml"
            params.write_text(yaml.safe_dump(data))
            r, w = peak_rss_bytes(params, Path(tmp) / "rec")
            steps.append(hold * 1000.0)  # 1 kHz; the motion's steps are common to all runs
            rss.append(r)
            wall.append(w)
    bytes_per_step = float(np.polyfit(steps, rss, 1)[0])
    seconds_per_step = float(np.polyfit(steps, wall, 1)[0])
    print(json.dumps({
        "machine": platform.processor() or platform.machine(),
        "holds_s": args.holds,
        "peak_rss_mb": [round(r / 1e6, 1) for r in rss],
        "wall_s": [round(w, 2) for w in wall],
        "bytes_per_joint_step": round(bytes_per_step / 6, 1),
        "assumed_bytes_per_joint_step": budget.BYTES_PER_JOINT_STEP,
        "seconds_per_joint_step": seconds_per_step / 6,
        "assumed_seconds_per_joint_step": budget.SECONDS_PER_JOINT_STEP,
    }, indent=2))  # fmt: skip


if __name__ == "__main__":
    main()
