"""A campaign (or the demo's episodes) from process start to exit, record + report, against
the converged floor measured in the same run (issue 31 items 2 and 3).

Runs the real commands as child processes, exactly as a user types them:

- campaign mode (default): ``pipeline record --params P --campaign bench -j J --out R`` on
  ``params.yaml`` plus one extra campaign (``paper-realistic``, ``--controllers`` x
  ``--seeds``, ``keep_bags: {every: K}``), then ``pipeline report --recordings R/bench``;
- ``--demo``: what ``make demo``'s DVC stages run, without DVC: ``pipeline record --params
  params.yaml --out R`` (the hand-listed episodes), ``pipeline record --campaign C`` for
  each of ``campaigns`` (with dvc.yaml's ``-j``), then ``pipeline report --baseline pid``.

Per command: wall (start to exit, imports included) and CPU (user + system of the child
and its workers). The floor (``benches/floor.py``) is measured before and after the
commands; the episodes' control steps come from the report's ``metrics.json``
(``end_s`` per episode, pre-roll included). The wall figure is set against the floor of
all steps on ``-j`` cores, the CPU figure against the CPU floor on one. With ``-j`` above
1 every figure is also given ``at_jobs_*``: against the floor measured with ``-j`` floor
loops at once (``floor.measure_floor_jobs``), the peer of work spread over ``-j`` workers.

``--repo`` runs another checkout's code (e.g. a ``git archive`` of ``main``) with this
bench's floor, for a before/after on the same load. Output stays under ``--work``
(default: a temporary directory, removed).

Usage: python benches/campaign_e2e.py [--seeds 50] [--controllers pid,ctc]
[--keep-every 20] [-j 2] [--demo] [--repo PATH] [--work DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from floor import (
    REPO,
    Floor,
    floor_fields,
    floor_summary,
    measure_floor,
    measure_floor_jobs,
    steps_in_report,
    uptime,
)


def _demo_campaign_jobs() -> list[str]:
    """The ``-j N`` of dvc.yaml's campaign stage (``[]``: none), as ``make demo`` runs it."""
    cmd = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"]["campaign"]["do"]["cmd"]
    words = cmd.split()
    for flag in ("-j", "--jobs"):
        if flag in words:
            return [flag, words[words.index(flag) + 1]]
    return []


def _children_cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _run(cmd: list[str], *, repo: Path) -> dict[str, float]:
    """Run a pipeline command as a child (``repo``'s code); its wall and CPU [s]."""
    env = dict(os.environ, PYTHONPATH=str(repo))
    c0, t0 = _children_cpu_s(), time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "pipeline", *cmd], cwd=repo, env=env, capture_output=True, text=True
    )
    wall_s, cpu_s = time.perf_counter() - t0, _children_cpu_s() - c0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: exit {done.returncode}: {done.stderr[-2000:]}")
    return {"wall_s": round(wall_s, 2), "cpu_s": round(cpu_s, 2)}


def _campaign_params(work: Path, *, seeds: int, controllers: list[str], every: int) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    campaign: dict[str, Any] = {
        "scenario": "paper-realistic", "controllers": controllers, "seeds": seeds
    }  # fmt: skip
    if every > 1:
        campaign["keep_bags"] = {"every": every}
    data.setdefault("extra_campaigns", {})["bench"] = campaign
    path = work / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=50)
    ap.add_argument("--controllers", default="pid,ctc")
    ap.add_argument("--keep-every", type=int, default=20, metavar="K")
    ap.add_argument("-j", "--jobs", type=int, default=2)
    ap.add_argument("--demo", action="store_true", help="params.yaml's hand-listed episodes")
    ap.add_argument("--repo", type=Path, default=REPO, help="the checkout whose code runs")
    ap.add_argument("--work", type=Path, default=None, help="keep outputs here")
    args = ap.parse_args()
    repo = args.repo.resolve()
    result: dict[str, Any] = {"repo": str(repo), "uptime_before": uptime(), "cpus": os.cpu_count()}
    if (repo / ".git").exists():
        result["commit"] = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True
        ).stdout.strip()
    floor: Floor = measure_floor()
    cores = 1 if args.demo else min(args.jobs, os.cpu_count() or 1)
    floor_j = measure_floor_jobs(cores) if cores > 1 else None
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        rec, rep = work / "rec", work / "rep"
        if args.demo:  # what `make demo`'s DVC stages run: episodes, each campaign, report
            params = str(REPO / "params.yaml")
            campaigns = list(yaml.safe_load(Path(params).read_text()).get("campaigns") or {})
            record_cmds = [["record", "--params", params, "--out", str(rec)]]
            record_cmds += [["record", "--params", params, "--out", str(rec), "--campaign", c,
                             *_demo_campaign_jobs()] for c in campaigns]  # fmt: skip
            report_cmd = ["report", "--recordings", str(rec), "--out", str(rep)]
            report_cmd += ["--baseline", "pid"]
        else:
            params_path = _campaign_params(
                work, seeds=args.seeds, controllers=args.controllers.split(","),
                every=args.keep_every,
            )  # fmt: skip
            record_cmds = [["record", "--params", str(params_path), "--campaign", "bench",
                            "-j", str(args.jobs), "--out", str(rec)]]  # fmt: skip
            report_cmd = ["report", "--recordings", str(rec / "bench"), "--out", str(rep)]
        runs = [_run(cmd, repo=repo) for cmd in record_cmds]
        record = {k: round(sum(r[k] for r in runs), 2) for k in ("wall_s", "cpu_s")}
        report = _run(report_cmd, repo=repo)
        sim = yaml.safe_load((REPO / "params.yaml").read_text())["sim"]
        control_dt_s = sim["physics_dt_s"] * sim["control_period_steps"]
        episodes, steps = steps_in_report(rep / "metrics.json", control_dt_s=control_dt_s)
    floor = floor.merged(measure_floor())
    if floor_j is not None:
        floor_j = floor_j.merged(measure_floor_jobs(cores))
    total = {k: round(record[k] + report[k], 2) for k in record}

    def at_jobs(wall_s: float, cpu_s: float) -> dict[str, Any]:
        """The same figure against the floor of ``-j`` loops at once (its own peer)."""
        if floor_j is None:
            return {}
        return floor_fields(
            floor_j, control_steps=steps, wall_s=wall_s, cpu_s=cpu_s, cores=cores, name="at_jobs"
        )

    result |= {
        "mode": "demo" if args.demo else "campaign",
        "command_record": ["pipeline " + " ".join(cmd) for cmd in record_cmds],
        "command_report": "pipeline " + " ".join(report_cmd),
        "episodes": episodes,
        "jobs": args.jobs,
        **floor_summary(floor),
        **({f"at_jobs_{k}": v for k, v in floor_summary(floor_j).items()} if floor_j else {}),
        "record": record
        | floor_fields(
            floor, control_steps=steps, wall_s=record["wall_s"], cpu_s=record["cpu_s"], cores=cores
        )
        | at_jobs(record["wall_s"], record["cpu_s"]),
        "report": report
        | floor_fields(
            floor, control_steps=steps, wall_s=report["wall_s"], cpu_s=report["cpu_s"], cores=cores
        )
        | at_jobs(report["wall_s"], report["cpu_s"]),
        "record_plus_report": total
        | floor_fields(
            floor, control_steps=steps, wall_s=total["wall_s"], cpu_s=total["cpu_s"], cores=cores
        )
        | at_jobs(total["wall_s"], total["cpu_s"]),
        "uptime_after": uptime(),
    }
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
