"""Helpers shared by the kinematics tests."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from pipeline.robots import RobotSpec
from pipeline.robots.dh_yaml import with_dh_rows


def wrapped_distance(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Largest per-joint angle difference [rad], modulo 2 pi (broadcasts over rows)."""
    d = np.asarray(a) - np.asarray(b)
    return np.abs((d + math.pi) % (2 * math.pi) - math.pi).max(axis=-1)


def with_dh(spec: RobotSpec, index: int, **changes: float) -> RobotSpec:
    """A copy of ``spec`` with joint ``index``'s DH row changed."""
    rows = list(spec.dh_rows or ())
    rows[index] = dataclasses.replace(rows[index], **changes)
    return with_dh_rows(spec, rows)


def with_limits(spec: RobotSpec, lower: np.ndarray, upper: np.ndarray) -> RobotSpec:
    """A copy of ``spec`` with new position limits [rad]."""
    joints = tuple(
        dataclasses.replace(
            j, limits=dataclasses.replace(j.limits, lower=float(lo), upper=float(hi))
        )
        for j, lo, hi in zip(spec.joints, lower, upper, strict=True)
    )
    return dataclasses.replace(spec, joints=joints)
