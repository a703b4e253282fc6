"""Loop realism between the plant and the controller: encoder, velocity estimate, delay.

The ideal loop (``LoopSettings()``) hands the controller the plant's state (plus the
scenario's independent Gaussian noise) and applies its torque at once, for the whole
control period. A scenario's ``loop`` settings change that, the same for every law:

- :class:`Sensor`: the measured position is quantised to the encoder's counts, and the
  measured velocity is, if asked, the measured position differenced over the control
  period and low-passed (first order), instead of the plant's velocity plus noise.
- :class:`Actuator`: a command computed at control instant ``k`` reaches the motors
  ``delay_s`` (plus, per period, a jitter drawn from the episode seed) later, at the
  resolution of the physics step; until the first command arrives the motors get 0.

The runner uses them only when ``LoopSettings.ideal`` is False, so the ideal loop's
recordings stay byte for byte what they were. The jitter has its own generator
(:func:`jitter_rng`): the sensor-noise draws of a seed do not move when jitter is on.
Every per-row draw (noise, jitter) is aligned to the motion's start
(:func:`align_to_motion`): however long the pre-roll held, the motion meets the same draws.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import SimulationError
from pipeline.settings import LoopSettings
from pipeline.trajectory import F64

JITTER_STREAM = 0x6A17
"""Second word of the jitter generator's seed, ``default_rng([seed, JITTER_STREAM])``."""


def jitter_rng(seed: int) -> np.random.Generator:
    """The episode's jitter generator: a stream of its own, so the noise draws stay put."""
    return np.random.default_rng([int(seed), JITTER_STREAM])


def align_to_motion(draws: NDArray[Any], *, start_row: int, cap_rows: int) -> None:
    """Give the motion's rows, in place, the per-row draws a full pre-roll would have
    given them: row ``start_row + j`` gets draw ``cap_rows + j`` (the rows before
    ``start_row``, already used, keep theirs; the last ``cap_rows - start_row`` rows, which
    the episode cannot reach, keep stale values). A pre-roll that ran to its cap changes
    nothing, so a fixed pre-roll's episode and a settled one meet the same noise, jitter
    and effort noise along the motion (and so do two laws whose pre-rolls differ)."""
    if 0 <= start_row < cap_rows:
        draws[start_row : len(draws) - (cap_rows - start_row)] = draws[cap_rows:]


def whole_steps(value_s: float, physics_dt_s: float, *, field: str) -> int:
    """``value_s`` as a whole number of physics steps.

    Raises:
        SimulationError: not finite, negative, or not a multiple of the physics step.
    """
    if not (isinstance(value_s, int | float) and math.isfinite(value_s) and value_s >= 0):
        raise SimulationError(f"{field}: expected a finite time >= 0 [s], got {value_s!r}")
    steps = round(value_s / physics_dt_s)
    if abs(steps * physics_dt_s - value_s) > 1e-9 * max(1.0, value_s / physics_dt_s):
        raise SimulationError(
            f"{field}: {value_s:g} s is not a whole number of physics steps of "
            f"{physics_dt_s:g} s (the delay's resolution; use a finer sim.physics_dt_s)"
        )
    return int(steps)


def check_loop(loop: LoopSettings, *, physics_dt_s: float, velocity_noise_std_rad_s: float) -> None:
    """Refuse loop settings the runner cannot honour (one line naming the field).

    Raises:
        SimulationError: a delay or jitter off the physics-step grid, or encoder
            velocity together with independent velocity noise.
    """
    whole_steps(loop.delay_s, physics_dt_s, field="loop.delay_s")
    whole_steps(loop.jitter_s, physics_dt_s, field="loop.jitter_s")
    if loop.velocity == "encoder" and velocity_noise_std_rad_s > 0:
        raise SimulationError(
            f"loop.velocity: 'encoder' differentiates the measured position, so "
            f"velocity_noise_std_rad_s ({velocity_noise_std_rad_s:g}) would not be used: "
            "set it to 0"
        )


class Sensor:
    """What the controller measures at each control instant.

    Position: the plant's plus the pre-drawn noise, then rounded to the nearest of
    ``encoder_counts_per_rev`` counts per revolution. Velocity: the plant's plus the
    pre-drawn noise (``velocity: plant``), or ``encoder``: ``(q_k - q_{k-1}) / T``
    through ``v_k = v_{k-1} + a (raw_k - v_{k-1})``, ``a = 1 - exp(-2 pi f_c T)`` (the
    first-order low-pass with cutoff ``f_c``, exact for a step; ``a = 1`` unfiltered),
    starting from rest (``v = 0``, ``q_{-1} = q_0``), as the episode does.

    Args:
        loop: the loop settings.
        control_dt_s: the control period ``T`` [s].
        noise_q, noise_qd: (N, n) pre-drawn noise per row, or None (none).
    """

    def __init__(
        self,
        loop: LoopSettings,
        *,
        control_dt_s: float,
        noise_q: F64 | None = None,
        noise_qd: F64 | None = None,
    ) -> None:
        counts = loop.encoder_counts_per_rev
        self.resolution_rad = 2.0 * math.pi / counts if counts else 0.0
        self.encoder_velocity = loop.velocity == "encoder"
        self.control_dt_s = control_dt_s
        cutoff = loop.velocity_cutoff_hz
        self.alpha = 1.0 - math.exp(-2.0 * math.pi * cutoff * control_dt_s) if cutoff > 0 else 1.0
        self.noise_q = noise_q
        self.noise_qd = noise_qd
        self._q_prev: F64 | None = None
        self._v: F64 | None = None
        self._raw: F64 = np.zeros(0)

    def measure(self, k: int, q_true: F64, qd_true: F64, q_out: F64, qd_out: F64) -> None:
        """Write row ``k``'s measured position and velocity into ``q_out``, ``qd_out``."""
        if self.noise_q is not None:
            np.add(q_true, self.noise_q[k], out=q_out)
        else:
            q_out[:] = q_true
        if self.resolution_rad:
            np.rint(np.divide(q_out, self.resolution_rad, out=q_out), out=q_out)
            q_out *= self.resolution_rad
        if not self.encoder_velocity:
            if self.noise_qd is not None:
                np.add(qd_true, self.noise_qd[k], out=qd_out)
            else:
                qd_out[:] = qd_true
            return
        if self._q_prev is None or self._v is None:
            self._q_prev = q_out.copy()
            self._v = np.zeros_like(q_out)
            self._raw = np.zeros_like(q_out)
        # v += alpha ((q - q_prev) / T - v), in that order, into a preallocated buffer
        raw, v = self._raw, self._v
        np.divide(np.subtract(q_out, self._q_prev, raw), self.control_dt_s, raw)
        v += np.multiply(self.alpha, np.subtract(raw, v, raw), raw)
        self._q_prev[:] = q_out
        qd_out[:] = v


class Actuator:
    """When each command reaches the motors, at the physics step's resolution.

    Command ``k``, computed at physics step ``k s`` (``s`` = steps per control period),
    arrives at step ``k s + D + J_k``: ``D`` the delay, ``J_k`` uniform in ``{0, .., J}``
    (the jitter, in steps) from :func:`jitter_rng`. At every physics step the motors apply
    the newest command that has arrived (an older one arriving later is stale and
    dropped, as a driver with sequence numbers drops it), 0 before the first.

    Args:
        loop: the loop settings (``delay_s``, ``jitter_s``: whole physics steps).
        rows: control instants in the episode.
        nstep: physics steps per control period.
        physics_dt_s: the physics step [s].
        seed: the episode seed (the jitter's draws).
    """

    def __init__(
        self, loop: LoopSettings, *, rows: int, nstep: int, physics_dt_s: float, seed: int
    ) -> None:
        delay = whole_steps(loop.delay_s, physics_dt_s, field="loop.delay_s")
        jitter = whole_steps(loop.jitter_s, physics_dt_s, field="loop.jitter_s")
        self.nstep = nstep
        self.delay_steps = delay
        self.jitter_steps = jitter
        # per command, the jitter drawn [physics steps]
        self._jitter = (
            jitter_rng(seed).integers(0, jitter + 1, size=rows)
            if jitter
            else np.zeros(rows, dtype=np.int64)
        )
        self.in_effect = np.empty(0, dtype=np.int64)
        self._runs: list[tuple[tuple[int, int], ...]] = []
        self._schedule(first_row=0)

    def _schedule(self, *, first_row: int) -> None:
        """(Re)compute which command is in effect at every physics step from
        ``first_row``'s period on (a command never arrives before it is computed, so the
        periods before ``first_row`` keep their schedule)."""
        nstep, rows = self.nstep, len(self._jitter)
        k = np.arange(rows)
        arrive = k * nstep + self.delay_steps + self._jitter
        total = rows * nstep
        newest = np.full(total, -1, dtype=np.int64)
        inside = arrive < total
        np.maximum.at(newest, arrive[inside], k[inside])
        np.maximum.accumulate(newest, out=newest)
        self.in_effect = newest  # per physics step, the command applied (-1: none yet)
        del self._runs[first_row:]
        for r in range(first_row, rows):
            period = newest[r * nstep : (r + 1) * nstep]
            cuts = [0, *(np.flatnonzero(np.diff(period)) + 1).tolist(), nstep]
            self._runs.append(tuple((b - a, int(period[a])) for a, b in itertools.pairwise(cuts)))

    def align_to_motion(self, *, start_row: int, cap_rows: int) -> None:
        """Give the commands from ``start_row`` on the jitter a full pre-roll of
        ``cap_rows`` would have given them (:func:`align_to_motion`)."""
        if self.jitter_steps and 0 <= start_row < cap_rows:
            align_to_motion(self._jitter, start_row=start_row, cap_rows=cap_rows)
            self._schedule(first_row=start_row)

    def advance(self, k: int, tau_cmd: F64, ctrl: F64, step: Callable[[int], None]) -> None:
        """Run control period ``k``'s physics steps with the commands in effect.

        Args:
            k: the control period.
            tau_cmd: (N, n) the commands so far (rows ``<= k`` filled).
            ctrl: MuJoCo's ``data.ctrl`` (written before each run of steps).
            step: steps the physics ``n`` times.
        """
        for n, j in self._runs[k]:
            if j < 0:
                ctrl[:] = 0.0
            else:
                ctrl[:] = tau_cmd[j]
            step(n)

    def applied(self, tau_cmd: F64, rows: int) -> F64:
        """The command in effect at each control instant's first physics step, (rows, n)
        (0 before the first arrives), unclipped."""
        j = self.in_effect[: rows * self.nstep : self.nstep][:rows]
        out: F64 = np.where((j >= 0)[:, None], tau_cmd[np.maximum(j, 0)], 0.0)
        return out
