"""One error base class; every user-facing failure is a subclass of it.

The CLI prints ``error: <message>`` (one line) and exits 1 for these; anything
else is a bug and shows a traceback.
"""

from __future__ import annotations

import difflib
import signal
import threading
from collections.abc import Iterable
from types import FrameType


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


class IdentificationError(PipelineError):
    """Dynamic identification cannot run: data unfit, unexcited parameters, a bad model file."""


def unknown_name_message(
    kind: str, name: object, valid: Iterable[str], *, where: str = "", also: Iterable[str] = ()
) -> str:
    """The one wording for a name that is not among the valid ones, with the nearest.

    E.g. ``controllers.slow.type: unknown controller 'ctcc' (did you mean 'ctc'?); valid:
    ctc, ctc_pid, pd_gravity, pid`` (MuJoCo Menagerie's difflib hint, mink's list).

    Args:
        kind: what the name names (``controller``, ``IK solver``, ``pid gain``).
        name: the name given (any value: it may come from YAML).
        valid: the valid names, in the order to list them.
        where: the field path or file the name came from ("" for none).
        also: further names a near miss may be (tried after ``valid``), not listed
            (e.g. installed plug-ins, which the caller lists its own way).
    """
    names = list(valid)
    hint = ""
    for pool in (names, list(also)):
        folded = {n.lower(): n for n in pool}  # a near miss in another case still matches
        near = difflib.get_close_matches(str(name).lower(), list(folded), n=1)
        if near:
            hint = f" (did you mean '{folded[near[0]]}'?)"
            break
    prefix = f"{where}: " if where else ""
    return f"{prefix}unknown {kind} '{name}'{hint}; valid: {', '.join(names) or 'none'}"


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, ``timeout``, a scheduler): raised where Ctrl-C would be.

    A subclass of :class:`KeyboardInterrupt`, so every cleanup that Ctrl-C runs
    (``finally`` blocks, ``except KeyboardInterrupt``) runs for SIGTERM too; the CLI then
    says ``terminated`` and exits :data:`EXIT_TERMINATED`.
    """


EXIT_INTERRUPTED = 130  # 128 + SIGINT, what shells report for Ctrl-C
EXIT_TERMINATED = 143  # 128 + SIGTERM


def interrupt_exit(err: BaseException) -> tuple[str, int]:
    """The word and exit code for an interrupt: ``terminated``/143 for SIGTERM, else
    ``interrupted``/130."""
    if isinstance(err, Terminated):
        return "terminated", EXIT_TERMINATED
    return "interrupted", EXIT_INTERRUPTED


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    # One cleanup: a second SIGTERM (a scheduler repeating itself) must not cut it short.
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated


def handle_sigterm() -> None:
    """Make SIGTERM raise :class:`Terminated` in the main thread (no-op elsewhere).

    Python's default for SIGTERM ends the process on the spot: no ``finally`` runs, so
    staging folders, partial bags and temporary copies would stay behind.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _raise_terminated)
