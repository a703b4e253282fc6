"""Seeds for numeric IK: a per-robot table of FK samples, searched in task space.

A local solver started near a solution converges in a few steps; started far
away it may stall in a local minimum or against a joint limit and restart. So
each robot gets a table of joint vectors drawn once per process (a fixed
generator: the same table every time) with their flange poses, and a k-d tree
over the poses. A target's nearest table poses give starts that are already
close in task space, and usually in the same branch of the inverse.

A pose's feature is its position [m] and its rotation matrix's entries scaled by
:data:`ROTATION_LENGTH_M` / sqrt 2, so that a small rotation of theta [rad] counts
as much as a displacement of theta x :data:`ROTATION_LENGTH_M`. A position-only
robot (fewer than 6 joints) is searched on position alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from pipeline.kinematics.fk import flange_model
from pipeline.kinematics.ik import position_only
from pipeline.robots.spec import RobotSpec

Array = NDArray[np.float64]

TABLE_SIZE = 32_768
"""Joint vectors in a robot's seed table (the Panda's took 0.15-0.36 s to build on a
shared, loaded 2-core machine)."""
TABLE_SEED = 0x5EED_7AB
"""Seed of the table's generator: the table, and so every IK answer, is reproducible."""
ROTATION_LENGTH_M = 0.2
"""How far [m] a displacement counts as one radian of rotation in the nearest-pose search
(about the wrist-to-flange lever: a wrist turn of theta moves the flange this much)."""


@dataclass(frozen=True, eq=False)
class SeedTable:
    """Joint vectors [rad] and a k-d tree over their flange poses (:func:`seed_table`)."""

    joints: Array
    """(n, dof) joint vectors [rad], within the limits."""
    tree: cKDTree
    position_only: bool

    def nearest(self, base_T_flange: Array, count: int) -> Array:
        """The ``count`` table joint vectors whose flange poses are nearest the target,
        nearest first: (count, dof) [rad]."""
        count = min(count, self.joints.shape[0])
        feature = pose_feature(base_T_flange[:3, 3], base_T_flange[:3, :3], self.position_only)
        _, index = self.tree.query(feature, k=count)
        out: Array = self.joints[np.atleast_1d(index)]
        return out


def pose_feature(position_m: Array, rotation: Array, position_only: bool) -> Array:
    """The search point of a pose (module doc): its position [m] (3,), then its scaled
    rotation entries (3, 3); the position alone for a position-only robot. Also for n
    poses at once: (n, 3) and (n, 3, 3) give (n, 12) or (n, 3)."""
    position = np.asarray(position_m, dtype=float)
    if position_only:
        return position.copy()
    scaled = rotation.reshape(*position.shape[:-1], 9) * (ROTATION_LENGTH_M / math.sqrt(2.0))
    out: Array = np.concatenate([position, scaled], axis=-1)
    return out


def sample_ranges(spec: RobotSpec) -> tuple[Array, Array]:
    """Where the table draws each joint [rad or m]: its limits, cut to one turn about
    the middle for a revolute joint that turns further (every angle once)."""
    lower, upper = spec.lower, spec.upper
    middle = 0.5 * (lower + upper)
    turns = np.array([j.kind != "prismatic" for j in spec.joints]) & (upper - lower > 2 * math.pi)
    return np.where(turns, middle - math.pi, lower), np.where(turns, middle + math.pi, upper)


@lru_cache(maxsize=16)
def seed_table(spec: RobotSpec) -> SeedTable:
    """The seed table of ``spec``, built once per spec and process (module doc)."""
    lo, hi = sample_ranges(spec)
    joints = np.random.default_rng(TABLE_SEED).uniform(lo, hi, (TABLE_SIZE, spec.dof))
    model, data, fid = flange_model(spec)
    positions = np.empty((TABLE_SIZE, 3))
    rotations = np.empty((TABLE_SIZE, 3, 3))
    for k, q in enumerate(joints):
        pin.forwardKinematics(model, data, q)
        placement = pin.updateFramePlacement(model, data, fid)
        positions[k] = placement.translation
        rotations[k] = placement.rotation
    only = position_only(spec)
    features = pose_feature(positions, rotations, only)
    return SeedTable(joints=joints, tree=cKDTree(features), position_only=only)


__all__ = ["ROTATION_LENGTH_M", "TABLE_SIZE", "SeedTable", "pose_feature", "seed_table"]
