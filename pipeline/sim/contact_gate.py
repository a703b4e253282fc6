"""Collision detection in the plant only where a contact is possible.

MuJoCo runs ``mj_collision`` in each of RK4's four stages, every physics step, whether
or not anything is near: on the UR5 plant (8 geoms, nothing within centimetres) it is
~40 % of ``mj_step``. A contact needs two geoms to touch, and the arm moves a bounded
distance per control period, so :class:`ContactGate` turns the plant's contacts off
(``mjDSBL_CONTACT``) for a control period when it has shown that no pair can touch
during it, and on otherwise. With no contact in the step, ``mj_collision`` with
contacts on finds none and everything downstream is guarded by ``ncon == 0``: the
state after the step is the same, bit for bit (``tests/sim/test_contact_gate.py``
compares gated and always-on episodes, one of them falling onto its pedestal).

The proof per period: at an anchor configuration ``q_a`` the planner's
``CollisionChecker`` (the plant's geometry and filtering, obstacles resolved exactly)
gives the distance ``d_p`` of every pair ``p`` that may collide and is closer than
``padding_m``. Two links move relative to each other only by the joints between them,
and a point beyond joint ``i`` moves at most ``R_i`` per radian of it
(``reach_terms_m``), so pair ``p`` comes at most ``R_p |dq|`` closer, ``R_p`` the root sum
of squares of ``R_i`` over its joints (all of them for the world's geometry, and
``padding_m`` against the whole arm's ``reach_bound_m`` for pairs beyond the padding).
The period is skipped while ``|q_k - q_a| + |qd_k| dt + a dt^2 / 2 < min_p d_p / R_p``:
``a`` bounds the change of the joint speed within the period, four times the last
period's observed acceleration and at least ``GATE_ACCEL_RAD_S2`` (20x what full torque
gives the UR5, UR10 or Panda at rest). Otherwise the gate checks again at ``q_k``; if
the arm is still that close, contacts stay on for ``cooldown_rows`` periods.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
from numpy.typing import NDArray

from pipeline.model.scene import Box
from pipeline.planning.collision import CollisionChecker, reach_bound_m, reach_terms_m
from pipeline.robots.spec import RobotSpec

GATE_PADDING_M = 0.15
"""How far the gate's clearance check looks [m]: beyond it a pair counts as this far."""
GATE_ACCEL_RAD_S2 = 2e4
"""The least joint acceleration the proof allows for within one period [rad/s^2]."""
GATE_COOLDOWN_ROWS = 50
"""Control periods with contacts on, unchecked, once the arm is found near something."""


class ContactGate:
    """Turns the plant model's contacts on and off per control period (see module)."""

    def __init__(
        self,
        model: mujoco.MjModel,
        spec: RobotSpec,
        *,
        obstacles: tuple[Box, ...],
        control_dt_s: float,
        padding_m: float = GATE_PADDING_M,
        accel_rad_s2: float = GATE_ACCEL_RAD_S2,
        cooldown_rows: int = GATE_COOLDOWN_ROWS,
    ) -> None:
        self.opt = model.opt
        self.on_flags = int(model.opt.disableflags) & ~int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        self.off_flags = self.on_flags | int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        self.checker = CollisionChecker(spec, obstacles=obstacles, padding_m=padding_m)
        self.padding_m = padding_m
        self.control_dt_s = control_dt_s
        self.accel_rad_s2 = accel_rad_s2
        self.cooldown_rows = cooldown_rows
        # per checker geom, its place in the chain (0: world or base, i + 1: joint i's link)
        m = self.checker.model
        link_index = {j.link_name: i + 1 for i, j in enumerate(spec.joints)}
        self.chain_of = [
            link_index.get(m.body(int(m.geom_bodyid[g])).name, 0) for g in range(m.ngeom)
        ]
        terms = reach_terms_m(spec)
        # R_p per (nearer, farther) chain index: the joints between them
        self.reach_m = [
            [math.sqrt(sum(r * r for r in terms[a:b])) for b in range(spec.dof + 1)]
            for a in range(spec.dof + 1)
        ]
        self.reach_all_m = reach_bound_m(spec)
        self.anchor: NDArray[np.float64] = np.full(spec.dof, np.nan)
        self.free_rad = -math.inf  # joint motion from the anchor that keeps contacts off
        self.last_qd: NDArray[np.float64] = np.full(spec.dof, np.nan)
        self.cooldown = 0
        self.off = False
        self.checks = 0
        self.opt.disableflags = self.on_flags

    def before_period(self, q: NDArray[np.float64], qd: NDArray[np.float64], speed: float) -> None:
        """Set the contacts for the control period starting at ``q`` with joint velocity
        ``qd`` (``speed``: its Euclidean norm); ``qd`` must stay unchanged until the next
        call (the loop passes its recorded rows)."""
        dt = self.control_dt_s
        accel = math.hypot(*(qd - self.last_qd).tolist()) / dt  # NaN on the first row
        self.last_qd = qd  # (a row of the episode's arrays: kept as it is, not copied)
        if self.cooldown:
            self.cooldown -= 1
            self._set(off=False)
            return
        ahead = speed * dt + 0.5 * max(self.accel_rad_s2, 4.0 * accel) * dt * dt
        if math.hypot(*(q - self.anchor).tolist()) + ahead < self.free_rad:
            self._set(off=True)
            return
        self.checks += 1
        self.anchor = q.copy()
        self.free_rad = self._free_rad(q)
        if ahead < self.free_rad and accel == accel:  # (NaN: contacts on)
            self._set(off=True)
        else:
            self.cooldown = self.cooldown_rows
            self.free_rad = -math.inf
            self._set(off=False)

    def _free_rad(self, q: NDArray[np.float64]) -> float:
        """min over pairs of distance / R_p at ``q`` [rad] (see module)."""
        pairs, dists = self.checker.pair_distances_m(q)
        free = self.padding_m / self.reach_all_m
        chain, reach = self.chain_of, self.reach_m
        for (g1, g2), d in zip(pairs.tolist(), dists.tolist(), strict=True):
            a, b = sorted((chain[g1], chain[g2]))
            r = reach[a][b]
            if r > 0.0:
                free = min(free, d / r)
        return free

    def _set(self, *, off: bool) -> None:
        if off != self.off:
            self.opt.disableflags = self.off_flags if off else self.on_flags
            self.off = off
