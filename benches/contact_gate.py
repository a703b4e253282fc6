"""The plant's contact gate (``pipeline.sim.contact_gate``): the control loop and the whole
episode with the gate and with MuJoCo's collision detection in every step, against the
converged floor, same run.

Episodes: ``paper-realistic`` pid and ctc (the campaign's laws), seed 1 (a drawn plant,
friction, damping, sensor noise), as ``benches/record.py`` runs them (``run_one``: plant
and controller setup, loop, contact check, bag write; the loop timed on its own). Each
figure is the best of ``--repeat``, gated and always-on interleaved; the floor
(``benches/floor.py``) is measured before and after. That the bags are the same is
``tests/sim/test_contact_gate.py``'s and bagdiff's (docs/BENCHMARKS.md).

Usage: python benches/contact_gate.py [--repeat 3]
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benches"))

from floor import floor_summary, measure_floor, uptime  # noqa: E402
from record import LoopProbe, _episodes  # noqa: E402

import pipeline.sim.runner as runner  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from campaign_profile import episode_wall_s

    probe = LoopProbe()
    probe._replay = lambda *a, **k: None  # type: ignore[method-assign]  (loop timing only)
    cases = [c for c in _episodes() if c[0] in ("realistic-pid", "realistic-ctc")]
    original = runner.run_episode
    load0 = uptime()
    floor = measure_floor()
    inf = float("inf")
    best: dict[str, dict[str, float]] = {}
    for _ in range(args.repeat):
        for gate in (True, False):
            runner.run_episode = functools.partial(original, contact_gate=gate)  # type: ignore[assignment]
            for name, episode, plan in cases:
                whole_s, steps = episode_wall_s(episode, plan)
                key = f"{name} {'gated' if gate else 'always-on'}"
                mine = best.setdefault(key, {"whole": inf, "loop": inf, "loop_cpu": inf})
                mine["steps"] = steps
                mine["whole"] = min(mine["whole"], whole_s)
                mine["loop"] = min(mine["loop"], probe.wall_s)
                mine["loop_cpu"] = min(mine["loop_cpu"], probe.cpu_s)
    runner.run_episode = original  # type: ignore[assignment]
    floor = floor.merged(measure_floor())
    out: dict[str, Any] = floor_summary(floor)
    for key, b in best.items():
        per_step = 1e6 / b["steps"]
        out[key] = {
            "control_steps": int(b["steps"]),
            "loop_us_per_step": round(b["loop"] * per_step, 2),
            "loop_x_floor": round(b["loop"] * per_step / floor.us_per_control_step, 3),
            "loop_cpu_x_floor_cpu": round(
                b["loop_cpu"] * per_step / floor.cpu_us_per_control_step, 3
            ),
            "whole_us_per_step": round(b["whole"] * per_step, 2),
            "whole_x_floor": round(b["whole"] * per_step / floor.us_per_control_step, 3),
        }
    out["uptime_before"], out["uptime_after"] = load0, uptime()
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
