"""Defaults of ``pipeline identify`` (no heavy imports: the CLI reads them at start-up)."""

from __future__ import annotations

DEFAULT_CUTOFF_HZ = 5.0
"""Zero-phase low-pass cutoff [Hz]: ten times a 0.1 Hz, 5-harmonic excitation's top."""
DEFAULT_MIN_SPEED_RAD_S = 0.02
"""Joint samples slower than this are left out (sticking friction is no sign(qd))."""
DEFAULT_MAX_CONDITION = 1e4
"""Pivots of the unit-norm-column regressor below 1/this of the first are unexcited."""
