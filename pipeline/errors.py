"""One error base class; every user-facing failure is a subclass of it.

The CLI prints ``error: <message>`` (one line) and exits 1 for these; anything
else is a bug and shows a traceback.
"""

from __future__ import annotations


class PipelineError(Exception):
    """Base class of all errors that are the user's input, not our bug."""


class SpecError(PipelineError):
    """A robot description (YAML) is invalid or unknown."""


class ModelError(PipelineError):
    """A model cannot be built or lacks what a command needs (e.g. dynamics)."""


class KinematicsError(PipelineError):
    """IK found no solution, or the robot geometry does not fit a solver."""


class ParamsError(PipelineError):
    """``params.yaml`` (scenarios, episodes, gains) is invalid."""


class PlanningError(PipelineError):
    """No collision-free path, or a start/goal in collision or out of limits."""


class SimulationError(PipelineError):
    """An episode diverged or could not run."""


class RecordingError(PipelineError):
    """A recording is missing, truncated, corrupt or lacks expected topics."""


class ReportError(PipelineError):
    """The report cannot be written from the given recordings."""


class TeachError(PipelineError):
    """The teach page cannot start (e.g. its port is in use)."""
