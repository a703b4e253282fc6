"""Defaults of ``pipeline identify`` (no heavy imports: the CLI reads them at start-up)."""

from __future__ import annotations

DEFAULT_CUTOFF_HZ = 5.0
"""Zero-phase low-pass cutoff [Hz]: ten times a 0.1 Hz, 5-harmonic excitation's top."""
DEFAULT_MIN_SPEED_RAD_S = 0.02
"""Joint samples slower than this are left out (sticking friction is no sign(qd))."""
DEFAULT_MAX_CONDITION = 1e4
"""Pivots of the unit-norm-column regressor below 1/this of the first are unexcited."""
DEFAULT_EVALUATIONS = 6000
"""Objective evaluations an excitation design spends by default (L-BFGS-B's finite-difference
gradients included: 1 + the free coefficients each). Picked from what the former default,
a 30 s wall-clock budget, got on this 2-core machine (its restarts ran past half of it,
to the 30 s): UR5 6931 (4.3 ms each, mid posture zeros) and 6406 (bent), Panda 2783 at
load 4 (5.7 ms each of CPU: about 5200 in 30 s when quiet). 6000 is about 25 s for the UR5
and 35 s for the Panda on a quiet machine, longer under load, and the same design."""
DEFAULT_BUDGET_S = 600.0
"""Wall-clock safety cap of an excitation design [s]: past it the design fails in one
line, it never returns a design cut short by machine load (17x the Panda's quiet time)."""
