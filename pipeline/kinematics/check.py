"""The kinematics notes' validation flow: random joints -> FK -> IK -> FK.

Configurations are drawn uniformly within the joint limits (seeded), so every
target is reachable. IK starts from its default seed (middle of the joint
range). Every returned solution is checked by forward kinematics (the robot's
Pinocchio model, whatever format it came from); a sample's errors are the worst
over its solutions. A robot with fewer than 6 joints has position-only IK: its
orientation error is reported but not judged. Targets (seeds/001): position error
< 0.1 mm, orientation error < 0.01 rad, solve time < 5 ms (judged on the 99th
percentile), plus a minimum success rate (a solve that returns nothing, or a
solution outside the error targets, is a failure).

Outputs in the chosen folder: ``ik_check.json`` (the summary) and
``error_map.png``: position and orientation error of each sample over the
workspace, folded about the base axis (radial distance r = sqrt(x^2 + y^2) vs
height z of the flange), with failures marked.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import KinematicsError
from pipeline.fsutil import atomic_write_bytes
from pipeline.kinematics.fk import flange_pose
from pipeline.kinematics.ik import IKOptions, pose_error, position_only
from pipeline.kinematics.solvers import make_solver
from pipeline.robots.spec import RobotSpec

POSITION_TARGET_M = 1e-4
ORIENTATION_TARGET_RAD = 1e-2
TIME_TARGET_MS = 5.0
DEFAULT_MIN_SUCCESS_RATE = 0.995
SUMMARY_FILE = "ik_check.json"
MAP_FILE = "error_map.png"


@dataclass(frozen=True)
class Stats:
    """Max and median [unit in the field name of the owner]."""

    max: float
    median: float


@dataclass(frozen=True)
class TimeStats:
    """Solve time statistics [ms]."""

    mean: float
    median: float
    p99: float


@dataclass(frozen=True)
class IKCheckReport:
    """Outcome of :func:`run_ik_check` (errors over successful samples' solutions)."""

    robot: str
    solver: str
    position_only: bool
    samples: int
    seed: int
    successes: int
    success_rate: float
    solutions_checked: int
    position_error_m: Stats
    orientation_error_rad: Stats
    solve_time_ms: TimeStats
    targets: dict[str, float]
    checks: dict[str, bool]
    passed: bool
    summary_json: str
    error_map_png: str

    def to_json(self) -> dict[str, Any]:
        """Plain dict; NaN (no sample solved) becomes None so the JSON stays valid."""
        out: dict[str, Any] = _no_nan(asdict(self))
        return out


def _no_nan(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _no_nan(v) for k, v in obj.items()}
    if isinstance(obj, float) and math.isnan(obj):
        return None
    return obj


@dataclass(frozen=True, eq=False)
class RoundTrips:
    """Per-sample outcome of FK -> IK -> FK on random configurations.

    Attributes:
        flange_position_m: (N, 3) flange position of each sample's target [m].
        position_error_m: (N,) worst position error over the sample's solutions [m];
            NaN where IK returned nothing.
        orientation_error_rad: (N,) worst orientation error, same convention [rad].
        time_ms: (N,) solve time of each sample [ms].
        solutions_checked: solutions verified by FK over all samples.
        position_only: the robot's IK matches positions only (fewer than 6 joints), so
            :attr:`good` does not judge the orientation error.
    """

    flange_position_m: NDArray[np.float64]
    position_error_m: NDArray[np.float64]
    orientation_error_rad: NDArray[np.float64]
    time_ms: NDArray[np.float64]
    solutions_checked: int
    position_only: bool = False

    @property
    def good(self) -> NDArray[np.bool_]:
        """Samples solved within the notes' position and orientation targets (position
        only for a position-only robot)."""
        out: NDArray[np.bool_] = self.position_error_m < POSITION_TARGET_M
        if not self.position_only:
            out &= self.orientation_error_rad < ORIENTATION_TARGET_RAD
        return out


def sample_round_trips(
    spec: RobotSpec,
    *,
    solver_name: str,
    samples: int,
    seed: int,
    progress: Callable[[int], None] | None = None,
) -> RoundTrips:
    """Random joints within limits (seeded) -> FK -> IK (default seed) -> FK, per sample.

    Raises:
        KinematicsError: an unknown solver or one that does not fit the robot.
    """
    solver = make_solver(solver_name, spec, options=IKOptions(seed=seed))
    rng = np.random.default_rng(seed)
    qs = rng.uniform(spec.lower, spec.upper, (samples, spec.dof))
    pos_err = np.full(samples, np.nan)
    ang_err = np.full(samples, np.nan)
    times_ms = np.empty(samples)
    where = np.empty((samples, 3))
    n_solutions = 0
    for i, q in enumerate(qs):
        target = flange_pose(spec, q)
        where[i] = target[:3, 3]
        t0 = time.perf_counter_ns()
        result = solver.solve(target)
        times_ms[i] = (time.perf_counter_ns() - t0) * 1e-6
        if result.ok:
            errs = [pose_error(flange_pose(spec, s), target) for s in result.solutions]
            n_solutions += len(errs)
            pos_err[i] = max(e[0] for e in errs)
            ang_err[i] = max(e[1] for e in errs)
        if progress is not None:
            progress(1)
    return RoundTrips(where, pos_err, ang_err, times_ms, n_solutions, position_only(spec))


def run_ik_check(
    spec: RobotSpec,
    *,
    solver_name: str = "numeric",
    samples: int = 1000,
    seed: int = 0,
    out_dir: Path,
    min_success_rate: float = DEFAULT_MIN_SUCCESS_RATE,
    progress: Callable[[int], None] | None = None,
) -> IKCheckReport:
    """Run the round trip on ``samples`` random configurations and write the outputs.

    Args:
        spec: the robot.
        solver_name: registry name of the IK solver.
        samples: number of random joint configurations (>= 1).
        seed: seeds the configurations and the solver's restarts.
        out_dir: folder for ``ik_check.json`` and ``error_map.png`` (created).
        min_success_rate: fraction of samples that must pass, in [0, 1].
        progress: called with 1 after each sample (for a progress bar).

    Raises:
        KinematicsError: bad arguments, an unknown solver or one that does not fit.
    """
    if samples < 1:
        raise KinematicsError(f"ik-check needs --samples >= 1, got {samples}")
    if not 0.0 <= min_success_rate <= 1.0:
        raise KinematicsError(f"min success rate must be in [0, 1], got {min_success_rate}")
    trips = sample_round_trips(
        spec, solver_name=solver_name, samples=samples, seed=seed, progress=progress
    )
    pos_err, ang_err, times_ms = trips.position_error_m, trips.orientation_error_rad, trips.time_ms
    where, n_solutions = trips.flange_position_m, trips.solutions_checked
    good = trips.good
    solved = np.isfinite(pos_err)
    successes = int(good.sum())
    pos = _stats(pos_err[solved])
    ang = _stats(ang_err[solved])
    tms = TimeStats(
        mean=float(times_ms.mean()),
        median=float(np.median(times_ms)),
        p99=float(np.percentile(times_ms, 99)),
    )
    rate = successes / samples
    checks = {
        "position_error": bool(solved.any()) and pos.max < POSITION_TARGET_M,
        # not judged where IK is position-only
        "orientation_error": trips.position_only
        or (bool(solved.any()) and ang.max < ORIENTATION_TARGET_RAD),
        "solve_time": tms.p99 < TIME_TARGET_MS,
        "success_rate": rate >= min_success_rate,
    }
    out_dir.mkdir(parents=True, exist_ok=True)
    summary_path = out_dir / SUMMARY_FILE
    map_path = out_dir / MAP_FILE
    report = IKCheckReport(
        robot=spec.name,
        solver=solver_name,
        position_only=trips.position_only,
        samples=samples,
        seed=seed,
        successes=successes,
        success_rate=rate,
        solutions_checked=n_solutions,
        position_error_m=pos,
        orientation_error_rad=ang,
        solve_time_ms=tms,
        targets={
            "position_error_m": POSITION_TARGET_M,
            "orientation_error_rad": ORIENTATION_TARGET_RAD,
            "solve_time_p99_ms": TIME_TARGET_MS,
            "success_rate": min_success_rate,
        },
        checks=checks,
        passed=all(checks.values()),
        summary_json=str(summary_path),
        error_map_png=str(map_path),
    )
    _write_map(map_path, report, where, pos_err, ang_err, good)
    atomic_write_bytes(summary_path, (json.dumps(report.to_json(), indent=2) + "\n").encode())
    return report


def _stats(values: NDArray[np.float64]) -> Stats:
    if values.size == 0:
        return Stats(max=math.nan, median=math.nan)
    return Stats(max=float(values.max()), median=float(np.median(values)))


def _write_map(
    path: Path,
    report: IKCheckReport,
    where: NDArray[np.float64],
    pos_err: NDArray[np.float64],
    ang_err: NDArray[np.float64],
    good: NDArray[np.bool_],
) -> None:
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    radial = np.hypot(where[:, 0], where[:, 1])
    height = where[:, 2]
    solved = np.isfinite(pos_err)
    floor = 1e-17  # log of an exact zero error
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), sharey=True, constrained_layout=True)
    panels = (
        (pos_err, "log10 position error [m]", POSITION_TARGET_M),
        (ang_err, "log10 orientation error [rad]", ORIENTATION_TARGET_RAD),
    )
    for ax, (err, label, target) in zip(axes, panels, strict=True):
        if solved.any():
            hb = ax.hexbin(
                radial[solved],
                height[solved],
                C=np.log10(np.maximum(err[solved], floor)),
                reduce_C_function=np.max,
                gridsize=18,
                cmap="viridis",
                vmax=max(math.log10(target), float(np.log10(np.maximum(err[solved], floor)).max())),
            )
            fig.colorbar(hb, ax=ax, label=f"{label}, max per cell (top >= target)")
        bad = ~good
        if bad.any():
            ax.scatter(radial[bad], height[bad], marker="x", color="red", s=30,
                       label=f"failed ({int(bad.sum())})")  # fmt: skip
            ax.legend(loc="upper right")
        ax.set_xlabel("radial distance from base axis r [m]")
        ax.set_title(label.replace("log10 ", ""))
    axes[0].set_ylabel("height z [m]")
    verdict = "PASS" if report.passed else "FAIL"
    targets = "< 0.1 mm (position-only IK)" if report.position_only else "< 0.1 mm, < 0.01 rad"
    fig.suptitle(
        f"IK check {verdict}: {report.robot}, {report.solver}, {report.samples} samples, "
        f"success {100 * report.success_rate:.2f} % (targets: {targets}, p99 < 5 ms)"
    )
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())


__all__ = [
    "DEFAULT_MIN_SUCCESS_RATE",
    "ORIENTATION_TARGET_RAD",
    "POSITION_TARGET_M",
    "TIME_TARGET_MS",
    "IKCheckReport",
    "RoundTrips",
    "Stats",
    "TimeStats",
    "run_ik_check",
    "sample_round_trips",
]
