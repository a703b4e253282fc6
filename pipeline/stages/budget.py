"""The resource budget: refuse, before any work, an episode that cannot fit in memory or time."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from pipeline.errors import ParamsError
from pipeline.params import Episode, Params
from pipeline.robots.loaders import load_spec

# What one control step costs, per joint, measured on the paper scenario (UR5, 1 kHz, full
# logging incl. the true state): peak RSS of `pipeline record` grows by ~3.6 kB per control
# step (6 joints) with the episode's length (benches/record_memory.py, docs/BENCHMARKS.md).
# The episode is held in memory whole (EpisodeResult arrays, then every CDR message, then
# the MCAP chunks), so this is what a longer episode adds. 800 B is the measured ~605 B
# plus a margin, so the estimate stays an upper bound when logging grows a little
# (tests/stages/test_record_budget.py fails when it no longer is).
BYTES_PER_JOINT_STEP = 800
# Wall time per physics step and joint: 5-14 us measured for a whole process, idle to busy
# machine (simulation, control, safety checks and writing), rounded up.
SECONDS_PER_JOINT_STEP = 2e-5
MAX_EPISODE_WALL_S = 2 * 3600.0  # longer is a typo in hold_s or physics_dt_s, not a study
MEMORY_SHARE = 0.8  # of MemAvailable, split between the episodes that run at once


@dataclass(frozen=True)
class EpisodeEstimate:
    """What an episode will cost, from its settings alone.

    Attributes:
        duration_s: simulated time (pre-roll + motion + hold) [s].
        control_steps: logged rows.
        physics_steps: MuJoCo steps.
        memory_bytes: peak memory the episode adds [B].
        wall_s: wall-clock time [s].
    """

    duration_s: float
    control_steps: int
    physics_steps: int
    memory_bytes: int
    wall_s: float


def estimate_episode(episode: Episode, *, dof: int, motion_s: float) -> EpisodeEstimate:
    """Estimate one episode's memory and time (``motion_s``: the reference's duration)."""
    sim = episode.sim
    # the longest it can run: the pre-roll's cap, the hold's (pipeline.sim.settling)
    scenario = episode.scenario
    duration_s = scenario.preroll_s + motion_s + max(scenario.hold_s, scenario.hold_max_s or 0.0)
    control_s = sim.physics_dt_s * sim.control_period_steps
    control_steps = int(duration_s / control_s) + 1
    physics_steps = control_steps * sim.control_period_steps
    return EpisodeEstimate(
        duration_s=duration_s,
        control_steps=control_steps,
        physics_steps=physics_steps,
        memory_bytes=control_steps * dof * BYTES_PER_JOINT_STEP,
        wall_s=physics_steps * dof * SECONDS_PER_JOINT_STEP,
    )


def available_memory_bytes() -> int:
    """``MemAvailable`` of /proc/meminfo (Linux); 8 GiB where it cannot be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 8 * 1024**3


def _size(n_bytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.3g} {unit}"
    return f"{n_bytes / 1e3:.3g} kB"


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{seconds / 3600:.3g} h"
    if seconds >= 60:
        return f"{seconds / 60:.3g} min"
    return f"{seconds:.3g} s"


def check_budget(
    params: Params,
    episodes: Sequence[Episode],
    *,
    motion_s: Mapping[str, float],
    jobs: int,
    memory_bytes: int | None = None,
) -> None:
    """Refuse, before any episode runs, one that cannot fit in memory or time.

    Args:
        motion_s: reference duration per scenario [s] (0 before planning: a lower bound).
        jobs: episodes run at once; each gets an equal share of the memory.
        memory_bytes: memory to share (default: :func:`available_memory_bytes`).

    Raises:
        ParamsError: one line with the estimate and the fields to change.
    """
    parallel = max(1, min(jobs, len(episodes)))
    share = MEMORY_SHARE * (memory_bytes or available_memory_bytes()) / parallel
    for episode in episodes:
        spec = load_spec(episode.scenario.robot)
        est = estimate_episode(
            episode, dof=spec.dof, motion_s=motion_s.get(episode.scenario_name, 0.0)
        )
        where = f"scenarios.{episode.scenario_name}.hold_s or sim.control_period_steps"
        what = (
            f"episode '{episode.name}' is {est.duration_s:.6g} s at "
            f"{est.control_steps:,} control steps x {spec.dof} joints"
        )
        if est.memory_bytes > share:
            per = f" (each of {parallel} parallel episodes)" if parallel > 1 else ""
            raise ParamsError(
                f"{params.source}: {what}: it would hold about {_size(est.memory_bytes)} in "
                f"memory, more than the {_size(share)} this machine can give it{per}; "
                f"lower {where}" + (" or --jobs" if parallel > 1 else "")
            )
        if est.wall_s > MAX_EPISODE_WALL_S:
            raise ParamsError(
                f"{params.source}: {what} ({est.physics_steps:,} physics steps): it would "
                f"run for about {_duration(est.wall_s)}, more than "
                f"{_duration(MAX_EPISODE_WALL_S)}; lower {where}, or raise sim.physics_dt_s"
            )
