"""Robot spec -> models: DH forward kinematics, MJCF (MuJoCo), URDF and Pinocchio."""

from __future__ import annotations
