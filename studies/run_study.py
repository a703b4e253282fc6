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
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

OUT = Path("studies/out")
SEEDS = 10
STUDIES: dict[str, dict[str, Any]] = {
    "panda": {
        "params": "studies/panda_published.yaml",
        "scenario": "panda-gaz",
        "campaign": "panda-published",
        "excite": [],
        "model": "panda-gaz.yaml",
    },
    "panda-links": {
        "params": "studies/panda_published.yaml",
        "scenario": "panda-gaz-links",
        "campaign": "panda-published-links",
        "excite": [],
        "model": "",
    },
    "ur5": {
        "params": "studies/ur5_friction_class.yaml",
        "scenario": "ur5-draws",
        "campaign": "ur5-friction-class",
        "excite": ["--periods", "2", "--mid", "0,-1.2,1.2,-1.0,0.5,0", "--evaluations", "4000"],
        "model": "ur5.yaml",
    },
    "ur5-own": {
        "params": "studies/ur5_friction_class.yaml",
        "scenario": "ur5-draws",
        "campaign": "ur5-friction-class-own",
        "excite": ["--periods", "2", "--mid", "0,-1.2,1.2,-1.0,0.5,0", "--evaluations", "4000"],
        "model": "ur5-s{seed}.yaml",
        "out": "ur5",
        "with": "ur5-friction-class",
    },
}
IDENTIFY_SEED = 100
"""The plant the one identified model is fitted on: a draw none of the episodes (seeds
0-9) runs on."""


def run(cmd: list[str]) -> None:
    print("+", " ".join(cmd), flush=True)
    if subprocess.run(cmd).returncode != 0:
        sys.exit(f"failed: {' '.join(cmd)}")


def identify(study: dict[str, Any], out: Path, seed: int) -> None:
    """One excitation of the plant ``seed`` draws, fitted into the study's model file."""
    model = out / "models" / str(study["model"]).format(seed=seed)
    if model.exists():
        return
    excite = out / "excite" if "{seed}" not in str(study["model"]) else out / f"excite-s{seed}"
    run([sys.executable, "-m", "pipeline", "identify", "excite", "--params", str(study["params"]),
         "--scenario", str(study["scenario"]), "--seed", str(seed), "--variant", "1",
         *study["excite"], "--out", str(excite), "--force"])  # fmt: skip
    run([sys.executable, "-m", "pipeline", "identify", "fit", str(excite), "--out", str(model)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("study", choices=sorted(STUDIES))
    parser.add_argument("-j", type=int, default=2)
    parser.add_argument("--step", choices=("all", "identify", "record", "table"), default="all")
    args = parser.parse_args()
    s = STUDIES[args.study]
    out = OUT / str(s.get("out", args.study))
    pipeline = [sys.executable, "-m", "pipeline"]
    if args.step in ("all", "identify") and s["model"]:
        (out / "models").mkdir(parents=True, exist_ok=True)
        if "{seed}" in str(s["model"]):  # one model per plant: seeds 0-9
            with ThreadPoolExecutor(args.j) as pool:
                list(pool.map(lambda seed: identify(s, out, seed), range(SEEDS)))
        else:
            identify(s, out, IDENTIFY_SEED)
    report = out / f"report-{s['campaign']}" if "with" in s else out / "report"
    if args.step in ("all", "record"):
        run([*pipeline, "record", "--params", str(s["params"]), "--campaign", str(s["campaign"]),
             "--out", str(out / "recordings"), "-j", str(args.j)])  # fmt: skip
        run([*pipeline, "report", "--recordings", str(out / "recordings" / str(s["campaign"])),
             "--out", str(report), "--baseline", "ctc_own" if "with" in s else "pid"])  # fmt: skip
    if args.step in ("all", "table"):
        parquets = [report / "campaigns" / f"{s['campaign']}.parquet"]
        if "with" in s:  # the CAD and one-model laws of the same seeds, for the comparison
            parquets.append(out / "report" / "campaigns" / f"{s['with']}.parquet")
        run([sys.executable, "studies/study_table.py", *map(str, parquets)])


if __name__ == "__main__":
    main()
