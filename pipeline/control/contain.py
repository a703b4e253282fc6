"""Plug-in controllers are contained, as ros2_control deactivates a misbehaving controller.

Plug-in code (an entry point or ``module:Object``; built-ins are ours and run bare) runs
under a :class:`PluginScope`: its ``import`` and ``__init__``, ``reset`` and every ``compute``
are timed against a per-call and a per-episode budget, and anything it raises (an
exception, ``sys.exit``, ``KeyboardInterrupt``, a blown budget), a non-finite or
wrong-shaped output, fails the episode with one :class:`PluginError` line naming the
controller, its origin, the call and the reason. ``compute`` gets read-only copies of its
inputs, so a law that writes into them cannot corrupt the recording.

Budgets: :data:`CALL_BUDGET_S` per call, :data:`IMPORT_BUDGET_S` for the import,
:data:`EPISODE_BUDGET_S` of wall clock per episode (from the import to the last call, the
simulation included, checked at each call). The environment variables
``ARMLAB_PLUGIN_CALL_BUDGET_S``, ``ARMLAB_PLUGIN_IMPORT_BUDGET_S`` and
``ARMLAB_PLUGIN_EPISODE_BUDGET_S`` override them (``record`` sets two from
``--plugin-call-budget-s`` and ``--plugin-episode-budget-s``; pool workers inherit them).
A call that never returns is interrupted by ``SIGALRM`` from a watchdog thread (main
thread only, Python-level code: a C loop that never checks signals is not).
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
"""Default wall-clock budget of one episode with a plug-in, from its import to its last
call, the simulation included [s]."""
WATCH_PERIOD_S = 0.02
"""How often the watchdog looks at the call under way [s] (the overrun resolution)."""
IMPORT_BUDGET_S = 30.0
"""Default wall-clock budget of importing a plug-in's module [s] (a cold import of a heavy
library takes seconds)."""
IMPORT_ENV = "ARMLAB_PLUGIN_IMPORT_BUDGET_S"
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
    import_s: float = IMPORT_BUDGET_S

    @staticmethod
    def from_env() -> Budget:
        """The budgets from the environment (see the module doc), else the defaults.

        Raises:
            PluginError: a value that is not a positive finite number of seconds.
        """
        return Budget(
            call_s=_env_seconds(CALL_ENV, CALL_BUDGET_S),
            episode_s=_env_seconds(EPISODE_ENV, EPISODE_BUDGET_S),
            import_s=_env_seconds(IMPORT_ENV, IMPORT_BUDGET_S),
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
        # the call under way, for the watchdog: its start (NaN: none) and its limit [s]
        self._started = math.nan
        self._limit = math.inf
        self._stop = threading.Event()

    def __enter__(self) -> PluginScope:
        self._deadline = time.monotonic() + self.budget.episode_s
        if threading.current_thread() is threading.main_thread():
            self._old_alarm = signal.signal(signal.SIGALRM, self._on_alarm)
            self._old_int = signal.getsignal(signal.SIGINT)
            if self._old_int is signal.default_int_handler:
                signal.signal(signal.SIGINT, self._on_sigint)
            self._handlers = True
            main = threading.main_thread().ident
            threading.Thread(
                target=self._watch, args=(main,), name="armlab-plugin-watchdog", daemon=True
            ).start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._started = math.nan
        if self._handlers:
            signal.signal(signal.SIGALRM, self._old_alarm)
            if signal.getsignal(signal.SIGINT) == self._on_sigint:
                signal.signal(signal.SIGINT, self._old_int)

    def _watch(self, main: int | None) -> None:
        """A call past its limit gets SIGALRM in the main thread (cheaper per call than a
        timer armed and disarmed around each one: a 1 kHz loop calls ``compute`` often)."""
        while not self._stop.wait(WATCH_PERIOD_S):
            started = self._started
            if started == started and time.monotonic() - started > self._limit and main:
                signal.pthread_kill(main, signal.SIGALRM)

    def _on_alarm(self, signum: int, frame: FrameType | None) -> None:
        if self._started == self._started:  # still inside the plug-in's call
            self._started = math.nan
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
        :class:`PluginError` (a :class:`PipelineError` raised by the plug-in's validation
        of its settings passes through)."""
        now = time.monotonic()
        left = self._deadline - now
        if left <= 0:
            raise self.fail(call, f"ran past the episode budget of {self.budget.episode_s:g} s")
        limit = min(self.budget.import_s if call == "import" else self.budget.call_s, left)
        try:
            return self._call(call, fn, now, limit)
        except _Overrun:  # (wherever the alarm landed while the call was under way)
            self._started = math.nan
            raise self.fail(call, self._overrun_reason(limit, left)) from None
        finally:
            if time.monotonic() - now > limit:
                self._started = math.nan
                raise self.fail(call, self._overrun_reason(limit, left)) from None

    def _call(self, call: str, fn: Callable[[], T], now: float, limit: float) -> T:
        self._limit = limit
        self._started = now
        try:
            out = fn()
        except _Overrun:
            raise
        except PipelineError:
            self._started = math.nan
            raise
        except KeyboardInterrupt:
            self._started = math.nan
            if self._sigint:
                raise
            raise self.fail(call, "raised KeyboardInterrupt") from None
        except SystemExit as err:
            self._started = math.nan
            raise self.fail(call, f"called sys.exit({err.code!r})") from None
        except RecursionError:
            self._started = math.nan
            raise self.fail(call, "RecursionError: maximum recursion depth exceeded") from None
        except BaseException as err:  # plug-in code may raise anything
            self._started = math.nan
            raise self.fail(call, f"raised {type(err).__name__}: {err}"[:300]) from None
        self._started = math.nan
        return out

    def _overrun_reason(self, limit: float, left: float) -> str:
        if limit < left:
            per = "to import" if limit == self.budget.import_s else "per call"
            return f"took longer than its budget of {limit:g} s {per}"
        return f"ran past the episode budget of {self.budget.episode_s:g} s"

    def wrap(self, controller: Any) -> ContainedController:
        """``controller`` with every call going through this scope."""
        return ContainedController(controller, self)


class ContainedController:
    """A plug-in controller seen through its :class:`PluginScope` (same interface)."""

    def __init__(self, inner: Any, scope: PluginScope) -> None:
        self._inner = inner
        self._scope = scope
        self._buffer: Any = np.empty((5, 0))
        self._views: tuple[Any, ...] | None = None

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
        if self._views is None or self._buffer.shape[1:] != np.shape(q):
            self._buffer = np.empty((5, *np.shape(q)))
            self._views = tuple(self._frozen_row(i) for i in range(5))
        buf = self._buffer  # private: a plug-in that writes here corrupts nothing recorded
        buf[0], buf[1], buf[2], buf[3], buf[4] = q, qd, q_ref, qd_ref, qdd_ref
        args = self._views
        out = self._scope.call("compute", lambda: self._inner.compute(*args, float(dt_s)))
        if not (
            isinstance(out, np.ndarray) and out.dtype == np.float64 and out.shape == buf.shape[1:]
        ):
            if isinstance(out, np.ndarray) and out.shape == buf.shape[1:] and np.isrealobj(out):
                out = out.astype(np.float64)  # float32, int: exact enough
            else:
                raise self._scope.fail(
                    "compute",
                    f"returned {type(out).__name__} of shape {np.shape(out)} and dtype "
                    f"{getattr(out, 'dtype', '?')}, expected {buf.shape[1]} real torques",
                )
        if not math.isfinite(math.fsum(out.tolist())) and not np.isfinite(out).all():
            raise self._scope.fail("compute", f"returned a non-finite torque {out.tolist()}")
        return out

    def _frozen_row(self, i: int) -> Any:
        view = self._buffer[i]
        view.flags.writeable = False
        return view

    def __getattr__(self, attr: str) -> Any:
        return getattr(self._inner, attr)


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
