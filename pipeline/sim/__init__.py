"""The episode runner: MuJoCo plant, control loop, divergence detection."""

from __future__ import annotations
