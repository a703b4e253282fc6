"""Collision checking of robot configurations with MuJoCo, and the motion-check resolution.

The MuJoCo model built from the spec already encodes which geometry pairs may
touch (contype/conaffinity bits: links vs links, links 2..n vs ground and
pedestal, links vs obstacles; plus ``<exclude>`` for link pairs that touch in
the zero pose). Robot–robot and robot–floor pairs come straight from
``mj_collision``. Obstacle boxes do not: MuJoCo's capsule–box collider misses
pairs within the margin (google-deepmind/mujoco#1473: the elbow 5 mm above a
shelf with a 10 mm margin gives no contact), so the checker's model replaces
each box by an enclosing capsule in ``mj_collision`` (capsule pairs are exact,
and the box is inside it, so no pair within the padding is missed), and a
contact with that capsule is only a candidate: its distance to the box itself
comes from ``mj_geomDistance`` (``resolve_bounds``). In free space a check
therefore costs ``mj_kinematics`` + ``mj_collision`` and nothing else.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import mujoco
import numpy as np
from numpy.typing import ArrayLike, NDArray

from pipeline.errors import PlanningError
from pipeline.model.mjcf import BOUND_SUFFIX, build_mujoco_model
from pipeline.model.scene import Box
from pipeline.robots.spec import RobotSpec

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


MIN_PADDING_M = 1e-3  # below this the check step (and planning) gets impractically fine


@functools.lru_cache(maxsize=32)
def shape_extent_m(spec: RobotSpec) -> float:
    """How far a link's own collision shapes (a URDF's meshes and primitives) reach from
    its link frame's origin [m]: 0 for a robot drawn by capsules alone."""
    if not any(j.shapes for j in spec.joints):
        return 0.0
    model = build_mujoco_model(spec)
    links = {j.link_name for j in spec.joints}
    extent = 0.0
    for g in range(model.ngeom):
        if model.body(model.geom_bodyid[g]).name in links:
            pos = float(np.linalg.norm(model.geom_pos[g]))
            extent = max(extent, pos + float(model.geom_rbound[g]))
    return extent


def reach_terms_m(spec: RobotSpec) -> list[float]:
    """``R_i`` [m] per joint: a bound on the distance of the geometry beyond joint ``i``
    from its axis (the summed link lengths for ``j >= i``, :meth:`RobotSpec.reach_m`, plus
    the largest capsule radius or, for a robot with its own shapes, how far they reach
    from their link frames); see ``reach_bound_m``."""
    r_max = max(max(j.collision_radius for j in spec.joints), shape_extent_m(spec))
    return [spec.reach_m(i) + r_max for i in range(spec.dof)]


def reach_bound_m(spec: RobotSpec) -> float:
    """``sqrt(sum_i R_i^2)`` [m/rad]: bound on how far any point of the arm moves per
    radian of (Euclidean) joint motion.

    A joint step ``dq`` moves any point by at most ``sum_i R_i |dq_i| <=
    ||dq||_2 * sqrt(sum_i R_i^2)``, where ``R_i`` bounds the distance of the
    geometry beyond joint ``i`` from its axis: the summed DH lengths
    ``|a_j| + |d_j|`` for ``j >= i`` plus the largest capsule radius. The same
    bound holds for the motion of one link relative to another.
    """
    return math.sqrt(sum(r * r for r in reach_terms_m(spec)))


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


@functools.lru_cache(maxsize=4096)
def coarse_to_fine(n_steps: int) -> NDArray[np.float64]:
    """1..n_steps (the motion's end first) in bisection order: each pass halves the gaps."""
    seen = np.zeros(n_steps + 1, dtype=bool)
    seen[[0, n_steps]] = True
    order = [np.array([n_steps])]
    gap = n_steps
    while gap > 1:
        gap = (gap + 1) // 2
        k = np.arange(gap, n_steps, gap)
        k = k[~seen[k]]
        seen[k] = True
        order.append(k)
    order.append(np.flatnonzero(~seen))
    out = np.concatenate(order).astype(np.float64)
    out.flags.writeable = False
    return out


@functools.lru_cache(maxsize=4096)
def _coarse_prefix(n_steps: int, count: int) -> tuple[int, ...]:
    """The first ``count`` entries of ``coarse_to_fine(n_steps)``, without the rest."""
    order = [n_steps]
    seen = {0, n_steps}
    gap = n_steps
    while gap > 1 and len(order) < count:
        gap = (gap + 1) // 2
        for k in range(gap, n_steps, gap):
            if k not in seen:
                seen.add(k)
                order.append(k)
                if len(order) == count:
                    break
    return tuple(order)


def _parenthesised(note: str) -> str:
    return f" ({note})" if note else ""


_PROBES = 6  # states a motion checks one by one before generating all of them


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
        self.model = build_mujoco_model(spec, obstacles=self.obstacles, obstacle_bounds=True)
        # a dozen geoms: the body-level BVH (midphase) costs more than it culls (~20 %
        # of mj_collision); contacts are the same without it
        self.model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_MIDPHASE)
        self.data = mujoco.MjData(self.model)
        # per geom: the box an enclosing capsule stands for, else -1
        box_of = np.full(self.model.ngeom, -1, dtype=np.int64)
        for box in self.obstacles:
            box_of[self.model.geom(box.name + BOUND_SUFFIX).id] = self.model.geom(box.name).id
        self.box_of: I64 = box_of
        self._box_of_list: list[int] = box_of.tolist()
        self._fromto = np.zeros(6)
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

    def pair_distances_m(self, q: ArrayLike) -> tuple[I64, F64]:
        """The geom pairs that may collide and are closer than ``padding_m`` at ``q``
        [rad] (or penetrate, with no padding), each with its signed distance.

        An obstacle box's enclosing capsule is replaced by the box and the exact
        robot-box distance. ``q`` is not checked (use the public checks for user input).

        Returns:
            (geom pairs, distances): (k, 2) MuJoCo geom ids of this checker's ``model``
            and (k,) signed distances [m], negative for penetration.
        """
        self.data.qpos[:] = q
        ncon = self.collide_current()
        contact = self.data.contact
        return self.resolve_bounds(contact.geom[:ncon], contact.dist[:ncon])

    def collide_current(self) -> int:
        """Candidate contacts at the configuration already in ``data.qpos``: 0 means
        nothing is within the padding; otherwise ``resolve_bounds`` tells which are."""
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_collision(self.model, self.data)
        return int(self.data.ncon)

    def resolve_bounds(self, geom_pairs: ArrayLike, dists: ArrayLike) -> tuple[I64, F64]:
        """Replace contacts with an obstacle's enclosing capsule by the exact robot–box
        distance (``mj_geomDistance``, at the kinematics in ``data``), keeping the pairs
        closer than ``padding_m`` (and penetrations when it is 0), one per robot geom
        and box.

        Args:
            geom_pairs: (k, 2) geom ids of ``mj_collision`` contacts.
            dists: (k,) their distances [m].

        Returns:
            (geom pairs, distances) with box geoms in place of their capsules.
        """
        box_of, padding = self._box_of_list, self._padding_m
        out_pairs: list[tuple[int, int]] = []
        out_dists: list[float] = []
        found = set()
        pair_list = np.asarray(geom_pairs, dtype=np.int64).reshape(-1, 2).tolist()
        dist_list = np.asarray(dists, dtype=np.float64).reshape(-1).tolist()
        for (g1, g2), d in zip(pair_list, dist_list, strict=True):
            b1, b2 = box_of[g1], box_of[g2]
            if b1 < 0 and b2 < 0:
                out_pairs.append((g1, g2))
                out_dists.append(d)
                continue
            robot, box = (g2, b1) if b1 >= 0 else (g1, b2)
            if (robot, box) in found:
                continue  # capsule pairs may give two contacts
            found.add((robot, box))
            d = self.box_distance_m(robot, box)
            if d < padding or d < 0.0:
                out_pairs.append((robot, box))
                out_dists.append(d)
        return (
            np.array(out_pairs, dtype=np.int64).reshape(-1, 2),
            np.array(out_dists, dtype=np.float64),
        )

    def box_distance_m(self, robot_geom: int, box_geom: int) -> float:
        """Signed distance [m] between a robot geom and a box at the kinematics in ``data``
        (``mj_geomDistance``; ``padding_m`` (at least 0) when farther)."""
        return float(
            mujoco.mj_geomDistance(
                self.model, self.data, robot_geom, box_geom, self._padding_m, self._fromto
            )
        )

    def motion_clear(self, qa: F64, qb: F64, *, step_rad: float) -> bool:
        """True when the states of the straight motion ``qa -> qb`` [rad], ``qb`` included,
        ``qa`` assumed checked, at most ``step_rad`` apart, are all clear by ``padding_m``.

        The states are checked coarse to fine (the order of OMPL's
        ``DiscreteMotionValidator``), so a collision usually shows up after a few
        checks: the first few one by one, the rest generated at once. A clear state
        costs ``mj_kinematics`` + ``mj_collision`` only.
        """
        delta = qb - qa
        n_steps = math.ceil(math.sqrt(float(np.dot(delta, delta))) / step_rad)
        if n_steps <= 1:
            return self.is_clear(qb)
        # most blocked motions end within a few states: those first, without generating
        # the motion's hundreds of states and their order (~40 us for a new length)
        probes = _coarse_prefix(n_steps, _PROBES)
        for k in probes:
            if not self.is_clear(qa + (k / n_steps) * delta):
                return False
        model, data = self.model, self.data
        qpos, kinematics, collision = data.qpos, mujoco.mj_kinematics, mujoco.mj_collision
        for q in qa + np.outer(coarse_to_fine(n_steps)[len(probes) :] / n_steps, delta):
            qpos[:] = q
            kinematics(model, data)
            collision(model, data)
            if data.ncon and not self._clear_contacts(data.ncon):
                return False
        return True

    def _clear_contacts(self, ncon: int) -> bool:
        """Are the ``ncon`` contacts in ``data`` all capsules around boxes that are
        themselves farther than ``padding_m``? (``is_clear``'s lean hot path)"""
        box_of, padding = self._box_of_list, self._padding_m
        model, data, fromto, distance = self.model, self.data, self._fromto, mujoco.mj_geomDistance
        done = None
        for pair in data.contact.geom[:ncon].tolist():
            if pair == done:
                continue  # a capsule pair's second contact: same distance
            done = pair
            g1, g2 = pair
            b1, b2 = box_of[g1], box_of[g2]
            if b1 >= 0:
                g1, g2 = g2, b1
            elif b2 >= 0:
                g2 = b2
            else:
                return False
            if distance(model, data, g1, g2, padding, fromto) < padding:
                return False
        return True

    def is_clear(self, q: ArrayLike) -> bool:
        """True when nothing is within ``padding_m`` at ``q`` [rad] (limits not checked)."""
        self.data.qpos[:] = q
        ncon = self.collide_current()
        return ncon == 0 or self._clear_contacts(ncon)

    def in_collision(self, q: ArrayLike) -> bool:
        """True when any pair penetrates at ``q`` [rad] (limits not checked)."""
        return bool((self.pair_distances_m(q)[1] < 0.0).any())

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
            m.geom(g).name.removesuffix(BOUND_SUFFIX)
            if int(m.geom_bodyid[g]) == 0
            else m.body(int(m.geom_bodyid[g])).name
            for g in range(m.ngeom)
        )

    def _pair_names(self, geom1: int, geom2: int) -> tuple[str, str]:
        labels = self.geom_labels
        a, b = sorted((labels[geom1], labels[geom2]))
        return a, b

    def contacts(self, q: ArrayLike) -> list[tuple[str, str]]:
        """Sorted unique pairs penetrating at ``q``: robot link (body) names, and the geom
        name (``ground``, ``pedestal``, an obstacle's name) for world geometry."""
        pairs, dists = self.pair_distances_m(self._as_q(q, "q"))
        return sorted(
            {
                self._pair_names(g1, g2)
                for (g1, g2), d in zip(pairs.tolist(), dists.tolist(), strict=True)
                if d < 0.0
            }
        )

    def clearance_m(self, q: ArrayLike) -> tuple[float, tuple[str, str] | None]:
        """Smallest distance [m] between pairs that may collide, if below ``padding_m``.

        Returns:
            (distance, pair), or (``padding_m``, None) when everything is farther.
        """
        pairs, dists = self.pair_distances_m(self._as_q(q, "q"))
        best: tuple[float, tuple[str, str] | None] = (self._padding_m, None)
        for (g1, g2), d in zip(pairs.tolist(), dists.tolist(), strict=True):
            if d < best[0]:
                best = (d, self._pair_names(g1, g2))
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
                + _parenthesised(self.pairs_note(pairs[0]))
            )
        return arr

    def pairs_note(self, pair: tuple[str, str]) -> str:
        """Why ``pair`` is checked at all: the SRDF used (which file) or that there is none."""
        if not all(name in self.spec_bodies for name in pair):
            return ""  # the ground, the pedestal or an obstacle: no SRDF disables it
        source = self.spec.collision_pairs_source
        if source.startswith("SRDF "):
            return f"the pair {pair[0]}-{pair[1]} is not disabled by {source}"
        return (
            f"the pair {pair[0]}-{pair[1]} is checked; {source}; `pipeline robots "
            "collision-matrix` writes an SRDF"
        )

    @functools.cached_property
    def spec_bodies(self) -> frozenset[str]:
        """The robot's body names (base and joint links)."""
        return frozenset((self.spec.base_link, *(j.link_name for j in self.spec.joints)))

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
                        + _parenthesised(self.pairs_note(pair))
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
            qs = qa + np.outer(np.arange(n_steps) / n_steps, qb - qa)
            inside = np.all((qs >= self._lower) & (qs <= self._upper), axis=1).tolist()
            for q, ok in zip(qs, inside, strict=True):
                if not ok or not self.is_clear(q):
                    bad: F64 = q
                    return bad
        return None
