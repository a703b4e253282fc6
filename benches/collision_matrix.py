"""The disabled-collision matrix of the 7-joint Panda with its meshes (issue 27).

Prints one JSON object: the wall time of ``collision_matrix`` (10,000 samples by default,
the target is <= 60 s) split into model build and sampling, the pairs per reason, and the
wall time of the whole ``pipeline robots collision-matrix`` command (process start-up,
loading the URDF and its meshes, writing the SRDF) on example-robot-data's Panda URDF
copied out without its SRDF.

Usage: python benches/collision_matrix.py [--samples 10000] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    from pipeline.planning.collision_matrix import collision_matrix
    from pipeline.robots.packages import package_search_path
    from pipeline.robots.urdf_loader import load_urdf

    erd = next(p / "example-robot-data" for p in package_search_path()
               if (p / "example-robot-data").is_dir())  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        urdf = Path(tmp) / "panda.urdf"
        shutil.copy(erd / "robots/panda_description/urdf/panda.urdf", urdf)
        (Path(tmp) / "panda.armlab.yaml").write_text(
            "locked: {panda_finger_joint1: 0.0}\nflange: panda_hand_tcp\n"
        )
        spec = load_urdf(urdf)
        t0 = time.perf_counter()
        collision_matrix(spec, samples=1, seed=args.seed)  # model build + default pose
        t_build = time.perf_counter() - t0
        t0 = time.perf_counter()
        matrix = collision_matrix(spec, samples=args.samples, seed=args.seed)
        t_matrix = time.perf_counter() - t0
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "pipeline", "robots", "collision-matrix", str(urdf),
             "--out", str(Path(tmp) / "out.srdf"), "--samples", str(args.samples),
             "--seed", str(args.seed)],
            check=True, cwd=REPO, capture_output=True,
            env={**os.environ, "PYTHONPATH": str(REPO)},
        )  # fmt: skip
        t_cli = time.perf_counter() - t0
    reasons = ("Adjacent", "Default", "Always", "Never")
    print(
        json.dumps(
            {
                "robot": "example-robot-data panda.urdf (7 joints, 11 links with meshes)",
                "samples": args.samples,
                "matrix_s": round(t_matrix, 3),
                "build_and_default_pose_s": round(t_build, 3),
                "per_sample_us": round(1e6 * (t_matrix - t_build) / args.samples, 1),
                "cli_total_s": round(t_cli, 3),
                "target_s": 60.0,
                "met": t_cli <= 60.0,
                "disabled": {r: matrix.count(r) for r in reasons},
                "checked_pairs": len(matrix.checked),
                "cpu": platform.processor() or platform.machine(),
                "load_avg": os.getloadavg(),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
