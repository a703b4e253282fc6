"""Collision checking of robot configurations with MuJoCo, and the motion-check resolution.

The MuJoCo model built from the spec already encodes which geometry pairs may
touch (contype/conaffinity bits: links vs links, links 2..n vs ground and
pedestal, links vs obstacles; plus ``<exclude>`` for link pairs that touch in
the zero pose), so a configuration is in collision exactly when
``mj_collision`` reports a contact. Nothing is re-filtered here.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import PlanningError
from pipeline.model.mjcf import build_mujoco_model
from pipeline.model.scene import Box
from pipeline.robots.spec import RobotSpec

F64 = NDArray[np.float64]


MIN_PADDING_M = 1e-3  # below this the check step (and planning) gets impractically fine


def reach_bound_m(spec: RobotSpec) -> float:
    """``sqrt(sum_i R_i^2)`` [m/rad]: bound on how far any point of the arm moves per
    radian of (Euclidean) joint motion.

    A joint step ``dq`` moves any point by at most ``sum_i R_i |dq_i| <=
    ||dq||_2 * sqrt(sum_i R_i^2)``, where ``R_i`` bounds the distance of the
    geometry beyond joint ``i`` from its axis: the summed DH lengths
    ``|a_j| + |d_j|`` for ``j >= i`` plus the largest capsule radius. The same
    bound holds for the motion of one link relative to another.
    """
    rows = [j.dh for j in spec.joints]
    r_max = max(j.collision_radius for j in spec.joints)
    reach = [sum(abs(r.a) + abs(r.d) for r in rows[i:]) + r_max for i in range(len(rows))]
    return math.sqrt(sum(r * r for r in reach))


def default_padding_m(spec: RobotSpec) -> float:
    """Largest planning padding [m]: half the smallest capsule radius."""
    return 0.5 * min(j.collision_radius for j in spec.joints)


def motion_check_step_rad(spec: RobotSpec, padding_m: float) -> float:
    """Joint-space step [rad] between collision checks along a motion.

    States are checked with geometry padded by ``padding_m``; a configuration
    between two checks is at most half a step from one of them, so it moves
    every point by at most ``padding_m / 2`` (see ``reach_bound_m``): the
    continuous motion is collision-free with the unpadded geometry.
    """
    return padding_m / reach_bound_m(spec)


class CollisionChecker:
    """Is a joint configuration collision-free (robot vs itself, ground, obstacles)?

    With ``padding_m > 0`` MuJoCo also reports pairs closer than the padding
    (geom margin): ``is_clear`` asks for that clearance (what the planner
    uses), ``in_collision``/``is_valid``/``contacts`` ask about real
    penetration. Holds its own ``MjModel``/``MjData``; not thread-safe.

    Args:
        spec: the robot.
        obstacles: boxes in the robot base frame.
        padding_m: clearance required by ``is_clear`` [m].
    """

    def __init__(
        self, spec: RobotSpec, *, obstacles: Sequence[Box] = (), padding_m: float = 0.0
    ) -> None:
        self.spec = spec
        self.obstacles = tuple(obstacles)
        self.model = build_mujoco_model(spec, obstacles=self.obstacles)
        self.data = mujoco.MjData(self.model)
        adr = [int(self.model.joint(name).qposadr[0]) for name in spec.joint_names]
        if adr != list(range(spec.dof)):
            # the model has exactly the arm's hinge joints, in order: anything else is a bug
            raise PlanningError(f"{spec.source}: unexpected MuJoCo joint layout {adr}")
        self._lower = spec.lower
        self._upper = spec.upper
        self._padding_m = 0.0
        self.padding_m = padding_m

    @property
    def padding_m(self) -> float:
        """Clearance ``is_clear`` requires [m]."""
        return self._padding_m

    @padding_m.setter
    def padding_m(self, value: float) -> None:
        if not (math.isfinite(value) and value >= 0.0):
            raise PlanningError(f"padding_m: expected a non-negative distance, got {value!r}")
        self._padding_m = float(value)
        # MuJoCo 4 gives a pair the sum of its two geoms' margins (checked by a test)
        self.model.geom_margin[:] = 0.5 * self._padding_m

    def _as_q(self, q: ArrayLike, what: str) -> F64:
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape != (self.spec.dof,):
            raise PlanningError(
                f"{what}: expected {self.spec.dof} joint positions "
                f"({', '.join(self.spec.joint_names)}), got shape {arr.shape}"
            )
        return arr

    def _collide(self, q: ArrayLike) -> int:
        self.data.qpos[:] = q
        return self.collide_current()

    def collide_current(self) -> int:
        """Contacts (within the padding) at the configuration already in ``data.qpos``."""
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_collision(self.model, self.data)
        return int(self.data.ncon)

    def is_clear(self, q: ArrayLike) -> bool:
        """True when nothing is within ``padding_m`` at ``q`` [rad] (limits not checked)."""
        return self._collide(q) == 0

    def in_collision(self, q: ArrayLike) -> bool:
        """True when any pair penetrates at ``q`` [rad] (limits not checked)."""
        ncon = self._collide(q)
        return any(c.dist < 0.0 for c in self.data.contact[:ncon]) if ncon else False

    def within_limits(self, q: ArrayLike) -> bool:
        """True when every joint of ``q`` [rad] is within its position limits."""
        arr = np.asarray(q, dtype=np.float64)
        return bool(np.all(arr >= self._lower) and np.all(arr <= self._upper))

    def is_valid(self, q: ArrayLike) -> bool:
        """Within the joint limits and not penetrating anything (padding not applied)."""
        arr = self._as_q(q, "q")
        return self.within_limits(arr) and not self.in_collision(arr)

    @functools.cached_property
    def geom_labels(self) -> tuple[str, ...]:
        """Per MuJoCo geom, the name a pair reports: the robot link (body) name, or the
        geom's own name for world geometry (``ground``, ``pedestal``, obstacles)."""
        m = self.model
        return tuple(
            m.geom(g).name if int(m.geom_bodyid[g]) == 0 else m.body(int(m.geom_bodyid[g])).name
            for g in range(m.ngeom)
        )

    def _pair_names(self, geom1: int, geom2: int) -> tuple[str, str]:
        labels = self.geom_labels
        a, b = sorted((labels[geom1], labels[geom2]))
        return a, b

    def contacts(self, q: ArrayLike) -> list[tuple[str, str]]:
        """Sorted unique pairs penetrating at ``q``: robot link (body) names, and the geom
        name (``ground``, ``pedestal``, an obstacle's name) for world geometry."""
        ncon = self._collide(self._as_q(q, "q"))
        pairs = {
            self._pair_names(int(c.geom1), int(c.geom2))
            for c in self.data.contact[:ncon]
            if c.dist < 0.0
        }
        return sorted(pairs)

    def clearance_m(self, q: ArrayLike) -> tuple[float, tuple[str, str] | None]:
        """Smallest distance [m] between pairs that may collide, if below ``padding_m``.

        Returns:
            (distance, pair), or (``padding_m``, None) when everything is farther.
        """
        ncon = self._collide(self._as_q(q, "q"))
        best: tuple[float, tuple[str, str] | None] = (self._padding_m, None)
        for c in self.data.contact[:ncon]:
            if c.dist < best[0]:
                best = (float(c.dist), self._pair_names(int(c.geom1), int(c.geom2)))
        return best

    def check_state(self, q: ArrayLike, what: str) -> F64:
        """Validate a start/goal: shape, joint limits, collisions.

        Returns:
            ``q`` as a float array.

        Raises:
            PlanningError: one line naming the state, the joint or contact pair, and
                what was expected.
        """
        arr = self._as_q(q, what)
        if not np.all(np.isfinite(arr)):
            raise PlanningError(f"{what}: joint positions must be finite, got {arr.tolist()}")
        for name, v, lo, hi in zip(
            self.spec.joint_names, arr, self._lower, self._upper, strict=True
        ):
            if not lo <= v <= hi:
                raise PlanningError(
                    f"{what}: {name} = {v:.6g} rad is outside its limits [{lo:.6g}, {hi:.6g}] rad"
                )
        pairs = self.contacts(arr)
        if pairs:
            shown = "; ".join(f"{a} touches {b}" for a, b in pairs)
            raise PlanningError(
                f"{what} is in collision ({shown}); expected a collision-free configuration"
            )
        return arr

    def planning_padding_m(self, start: F64, goal: F64) -> float:
        """Padding [m] for planning between ``start`` and ``goal`` (both collision-free).

        ``default_padding_m`` unless the start or goal is closer than twice that to
        something; then half their clearance, so both stay valid under the padding.

        Raises:
            PlanningError: start or goal closer than ``2 * MIN_PADDING_M`` to something.
        """
        saved = self._padding_m
        cap = 2.0 * default_padding_m(self.spec)
        try:
            self.padding_m = cap
            padding = cap / 2.0
            for what, q in (("start", start), ("goal", goal)):
                dist, pair = self.clearance_m(q)
                if dist / 2.0 < MIN_PADDING_M:
                    assert pair is not None
                    raise PlanningError(
                        f"{what}: {pair[0]} is {dist * 1e3:.2f} mm from {pair[1]}; expected at "
                        f"least {2e3 * MIN_PADDING_M:.0f} mm clearance for planning"
                    )
                padding = min(padding, dist / 2.0)
        finally:
            self.padding_m = saved
        return padding

    def first_invalid(self, path: F64, *, step_rad: float) -> F64 | None:
        """First configuration along the piecewise-linear ``path`` (K, n) that is out of
        limits or not clear by ``padding_m``, checked every <= ``step_rad`` [rad]."""
        for k in range(len(path)):
            qa = path[k]
            qb = path[k + 1] if k + 1 < len(path) else qa
            n_steps = max(1, math.ceil(float(np.linalg.norm(qb - qa)) / step_rad))
            for i in range(n_steps):
                q: F64 = qa + (qb - qa) * (i / n_steps)
                if not self.within_limits(q) or not self.is_clear(q):
                    return q
        return None
