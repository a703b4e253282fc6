"""Run one issue-28 study end to end: identify, record, report, table (docs/control.md,
"The studies on the fair footing").

    python studies/run_study.py panda|ur5 [-j 2] [--step all|identify|record|table]

From the repository root, with ``pipeline`` on the path. Outputs go to ``studies/out/``
(gitignored); each step skips what is already there (the record stage skips episodes
already recorded with the same settings and code). The params files hold the commands
each step runs (``studies/panda_published.yaml``, ``studies/ur5_friction_class.yaml``).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

OUT = Path("studies/out")
STUDIES = {
    "panda": {
        "params": "studies/panda_published.yaml",
        "scenario": "panda-gaz",
        "campaign": "panda-published",
        "excite": [],
        "model": "panda-gaz.yaml",
    },
    "ur5": {
        "params": "studies/ur5_friction_class.yaml",
        "scenario": "ur5-draws",
        "campaign": "ur5-friction-class",
        "excite": ["--periods", "2", "--mid", "0,-1.2,1.2,-1.0,0.5,0", "--evaluations", "4000"],
        "model": "ur5.yaml",
    },
}
IDENTIFY_SEED = 100
"""The plant the one identified model is fitted on: a draw none of the episodes (seeds
0-9) runs on."""


def run(cmd: list[str]) -> None:
    print("+", " ".join(cmd), flush=True)
    if subprocess.run(cmd).returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", choices=sorted(STUDIES))
    parser.add_argument("-j", type=int, default=2)
    parser.add_argument("--step", choices=("all", "identify", "record", "table"), default="all")
    args = parser.parse_args()
    s = STUDIES[args.study]
    out = OUT / args.study
    pipeline = [sys.executable, "-m", "pipeline"]
    model = out / "models" / str(s["model"])
    if args.step in ("all", "identify") and not model.exists():
        excite = out / "excite"
        run([*pipeline, "identify", "excite", "--params", str(s["params"]),
             "--scenario", str(s["scenario"]), "--seed", str(IDENTIFY_SEED), "--variant", "1",
             *s["excite"], "--out", str(excite), "--force"])  # fmt: skip
        run([*pipeline, "identify", "fit", str(excite), "--out", str(model)])
    if args.step in ("all", "record"):
        run([*pipeline, "record", "--params", str(s["params"]), "--campaign", str(s["campaign"]),
             "--out", str(out / "recordings"), "-j", str(args.j)])  # fmt: skip
        run([*pipeline, "report", "--recordings", str(out / "recordings" / str(s["campaign"])),
             "--out", str(out / "report"), "--baseline", "pid"])  # fmt: skip
    if args.step in ("all", "table"):
        parquet = out / "report" / "campaigns" / f"{s['campaign']}.parquet"
        run([sys.executable, "studies/study_table.py", str(parquet)])


if __name__ == "__main__":
    main()
