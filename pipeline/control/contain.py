"""Plug-in controllers are contained, as ros2_control deactivates a misbehaving controller.

Plug-in code (an entry point or ``module:Object``; built-ins are ours and run bare) runs
under a :class:`PluginScope`: its ``import`` and ``__init__``, ``reset`` and every ``compute``
are timed against a per-call and a per-episode budget, and anything it raises (an
exception, ``sys.exit``, ``KeyboardInterrupt``, a blown budget), a non-finite or
wrong-shaped output, fails the episode with one :class:`PluginError` line naming the
controller, its origin, the call and the reason. ``compute`` gets read-only copies of its
inputs, so a law that writes into them cannot corrupt the recording.

Budgets: :data:`CALL_BUDGET_S` per call, :data:`EPISODE_BUDGET_S` for the plug-in's calls
in one episode (import included); the environment variables ``ARMLAB_PLUGIN_CALL_BUDGET_S``
and ``ARMLAB_PLUGIN_EPISODE_BUDGET_S`` override them (``record`` and ``check-controller``
set them from ``--plugin-call-budget-s`` and ``--plugin-episode-budget-s``; pool workers
inherit them). A call that never returns is interrupted by ``SIGALRM`` (main thread only,
Python-level code: a C loop that never checks signals is bounded by killing its worker).
"""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import FrameType
from typing import Any, TypeVar

import numpy as np

from pipeline.errors import PipelineError

CALL_BUDGET_S = 1.0
"""Default wall-clock budget of one plug-in call [s] (import, ``__init__``, ``reset``,
``compute``)."""
EPISODE_BUDGET_S = 600.0
"""Default wall-clock budget of all of a plug-in's calls in one episode [s]."""
CALL_ENV = "ARMLAB_PLUGIN_CALL_BUDGET_S"
EPISODE_ENV = "ARMLAB_PLUGIN_EPISODE_BUDGET_S"

T = TypeVar("T")


class PluginError(PipelineError):
    """Plug-in code misbehaved: it raised, exited, overran its budget or returned garbage."""


@dataclass(frozen=True)
class Budget:
    """Wall-clock budgets [s] of a plug-in's calls."""

    call_s: float = CALL_BUDGET_S
    episode_s: float = EPISODE_BUDGET_S

    @staticmethod
    def from_env() -> Budget:
        """The budgets from the environment (see the module doc), else the defaults.

        Raises:
            PluginError: a value that is not a positive finite number of seconds.
        """
        return Budget(
            call_s=_env_seconds(CALL_ENV, CALL_BUDGET_S),
            episode_s=_env_seconds(EPISODE_ENV, EPISODE_BUDGET_S),
        )


def _env_seconds(key: str, default: float) -> float:
    raw = os.environ.get(key, "")
    if not raw:
        return default
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise PluginError(f"{key}={raw!r}: expected a positive number of seconds")
    return value


def set_budget_env(*, call_s: float | None, episode_s: float | None) -> None:
    """Set the budgets for this process and the workers it forks (CLI flags)."""
    for key, value in ((CALL_ENV, call_s), (EPISODE_ENV, episode_s)):
        if value is not None:
            if not (math.isfinite(value) and value > 0):
                raise PluginError(f"{key}: expected a positive number of seconds, got {value}")
            os.environ[key] = repr(float(value))


class _Overrun(BaseException):
    """Raised by SIGALRM inside plug-in code (a BaseException: plug-in code rarely catches it)."""


class PluginScope:
    """Where plug-in code runs for one episode: budgets, signals, one-line failures.

    Use as a context manager (it installs the SIGALRM and SIGINT handlers in the main
    thread), then :meth:`call` for the import and ``__init__`` and :meth:`wrap` for the
    controller.
    """

    def __init__(self, name: str, *, budget: Budget | None = None) -> None:
        self.name = name
        self.origin = _origin_before_import(name)
        self.budget = budget or Budget.from_env()
        self._deadline = math.inf
        self._handlers = False
        self._sigint = False

    def __enter__(self) -> PluginScope:
        self._deadline = time.monotonic() + self.budget.episode_s
        if threading.current_thread() is threading.main_thread():
            self._old_alarm = signal.signal(signal.SIGALRM, self._on_alarm)
            self._old_int = signal.getsignal(signal.SIGINT)
            if self._old_int is signal.default_int_handler:
                signal.signal(signal.SIGINT, self._on_sigint)
            self._handlers = True
        return self

    def __exit__(self, *exc: object) -> None:
        if self._handlers:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self._old_alarm)
            if signal.getsignal(signal.SIGINT) == self._on_sigint:
                signal.signal(signal.SIGINT, self._old_int)

    def _on_alarm(self, signum: int, frame: FrameType | None) -> None:
        raise _Overrun

    def _on_sigint(self, signum: int, frame: FrameType | None) -> None:
        self._sigint = True  # a real Ctrl-C, not a KeyboardInterrupt raised by plug-in code
        raise KeyboardInterrupt

    def fail(self, call: str, reason: str) -> PluginError:
        """The one line: controller, origin, call, reason."""
        return PluginError(f"controller '{self.name}' ({self.origin}): {call}: {reason}")

    def set_origin(self, origin: dict[str, str]) -> None:
        """Name where the code came from once it is imported (the module's file)."""
        self.origin = describe_origin(origin)

    def call(self, call: str, fn: Callable[[], T]) -> T:
        """Run ``fn`` (plug-in code for ``call``) within the budgets; any escape is a
        :class:`PluginError` (a :class:`PipelineError` from our own checks passes through,
        prefixed)."""
        now = time.monotonic()
        left = self._deadline - now
        if left <= 0:
            raise self.fail(call, f"episode budget of {self.budget.episode_s:g} s used up")
        limit = min(self.budget.call_s, left)
        armed = self._handlers
        if armed:
            signal.setitimer(signal.ITIMER_REAL, limit)
        try:
            out = fn()
        except _Overrun:
            raise self.fail(call, self._overrun_reason(limit, left)) from None
        except PipelineError:
            raise
        except KeyboardInterrupt:
            if self._sigint:
                raise
            raise self.fail(call, "raised KeyboardInterrupt") from None
        except SystemExit as err:
            raise self.fail(call, f"called sys.exit({err.code!r})") from None
        except RecursionError:
            raise self.fail(call, "RecursionError: maximum recursion depth exceeded") from None
        except BaseException as err:  # plug-in code may raise anything
            raise self.fail(call, f"raised {type(err).__name__}: {err}"[:300]) from None
        finally:
            if armed:
                signal.setitimer(signal.ITIMER_REAL, 0.0)
        took = time.monotonic() - now
        if took > limit:
            raise self.fail(call, self._overrun_reason(limit, left))
        return out

    def _overrun_reason(self, limit: float, left: float) -> str:
        if limit < left:
            return f"took longer than its budget of {limit:g} s per call"
        return f"ran past the episode budget of {self.budget.episode_s:g} s"

    def wrap(self, controller: Any) -> ContainedController:
        """``controller`` with every call going through this scope."""
        return ContainedController(controller, self)


class ContainedController:
    """A plug-in controller seen through its :class:`PluginScope` (same interface)."""

    def __init__(self, inner: Any, scope: PluginScope) -> None:
        self._inner = inner
        self._scope = scope
        self._dof: int | None = None

    @property
    def name(self) -> str:
        """The plug-in's name (as it says)."""
        return str(self._scope.call("name", lambda: self._inner.name))

    def gains_in_effect(self) -> dict[str, Any]:
        """The plug-in's gains (its own call, budgeted)."""
        gains = self._scope.call("gains_in_effect", self._inner.gains_in_effect)
        if not isinstance(gains, dict):
            raise self._scope.fail(
                "gains_in_effect", f"returned {type(gains).__name__}, not a dict"
            )
        return gains

    def reset(self) -> None:
        """The plug-in's ``reset`` (budgeted)."""
        self._scope.call("reset", self._inner.reset)

    def compute(self, q: Any, qd: Any, q_ref: Any, qd_ref: Any, qdd_ref: Any, dt_s: float) -> Any:
        """The plug-in's torque on read-only copies of its inputs; refused unless it is
        ``dof`` finite floats."""
        args = tuple(_frozen(a) for a in (q, qd, q_ref, qd_ref, qdd_ref))
        out = self._scope.call("compute", lambda: self._inner.compute(*args, float(dt_s)))
        try:
            tau = np.asarray(out, dtype=np.float64)
        except (TypeError, ValueError) as err:
            raise self._scope.fail("compute", f"returned {type(out).__name__}: {err}") from None
        if not (isinstance(out, np.ndarray) and np.isrealobj(out)) or tau.shape != q.shape:
            raise self._scope.fail(
                "compute",
                f"returned {type(out).__name__} of shape {np.shape(out)} and dtype "
                f"{getattr(out, 'dtype', '?')}, expected {q.shape[0]} real torques",
            )
        if not np.isfinite(tau).all():
            raise self._scope.fail("compute", f"returned a non-finite torque {tau.tolist()}")
        return tau

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._inner, attr)


def _frozen(a: Any) -> Any:
    copy = np.array(a, dtype=np.float64, copy=True)
    copy.flags.writeable = False
    return copy


def is_builtin(name: str) -> bool:
    """Whether controller ``name`` is one of ours (runs uncontained)."""
    from pipeline.control.registry import CONTROLLERS

    return name in CONTROLLERS


def describe_origin(origin: dict[str, str]) -> str:
    """A recorded origin in a few words."""
    kind = origin.get("kind", "")
    if kind == "entry_point":
        return (
            f"entry point {origin.get('value', '')} of {origin.get('distribution', '?')} "
            f"{origin.get('version', '')}".rstrip()
        )
    if kind == "module":
        return f"module {origin.get('path', '') or origin.get('object', '')}"
    return kind or "unknown origin"


def _origin_before_import(name: str) -> str:
    if ":" in name:
        return f"module {name.partition(':')[0]}"
    return "entry point"


@contextmanager
def contained_controller(
    name: str, build: Callable[[], Any], *, budget: Budget | None = None
) -> Iterator[Any]:
    """Build controller ``name`` with ``build()`` and yield it, contained if it is a plug-in.

    A built-in is yielded bare. A plug-in's import and ``__init__`` run in its scope, and the
    yielded controller calls through it until the block ends.
    """
    if is_builtin(name):
        yield build()
        return
    from pipeline.control.registry import controller_entry, controller_origin

    with PluginScope(name, budget=budget) as scope:
        scope.call("import", lambda: controller_entry(name))
        scope.set_origin(controller_origin(name))  # resolved: cached, imports nothing
        controller = scope.call("__init__", build)
        yield scope.wrap(controller)
