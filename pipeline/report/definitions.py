"""The report's "Definitions" section: each metric's definition as its catalog entry
(:data:`pipeline.analysis.catalog.METRICS`) says it, between the notes on errors, missing
values and reductions."""

from __future__ import annotations

from pipeline.analysis import catalog
from pipeline.analysis.aggregate import CONFIDENCE
from pipeline.constants import TOPIC_CONTROLLER_STATE, TOPIC_GROUND_TRUTH, TOPIC_JOINT_STATES
from pipeline.report.md import ENDED_EARLY, FLOOR, NOT_RECORDED, SALVAGE_CUT

_CS, _JS = f"`{TOPIC_CONTROLLER_STATE}`", f"`{TOPIC_JOINT_STATES}`"
# Where any metric the layout does not name goes (one bullet each, in catalog order).
_OTHER_METRICS = ("*",)
# The bullets in order: a text is a note, a tuple of metric names one bullet of their
# definitions (joined by "; ").
_LAYOUT: tuple[str | tuple[str, ...], ...] = (
    "error e(t) = reference − true joint position [rad] where the recording carries "
    f"the plant's true state (`{TOPIC_GROUND_TRUTH}`, simulation), else reference − "
    f"measured position as recorded on {_CS} (`error.positions`; a real robot's bag); "
    "the *error from* column of the episode table says which. Every error-based number "
    f"(max, RMS, at the target, settling, overshoot) uses every {_CS} message, at its "
    f"full rate; velocities (true where recorded) and efforts come from {_JS} (which may "
    "be decimated). Times count from the motion start: the pre-roll before it (the "
    "controller holding the start pose) takes no part.",
    ("max_abs_error", "rms_error"),
    ("final_error",),
    ("settling_time",),
    ("overshoot",),
    f"'{ENDED_EARLY}': the episode failed or its recording stops before the motion end, "
    "so its last samples are not at the target: error at the target, settling time and "
    "overshoot are not given (max and RMS are, over what was recorded).",
    f"'{SALVAGE_CUT}': a salvaged recording (`--salvage`) whose motion end is not "
    "recorded: where it stops is where the file is damaged, not the episode's end.",
    ("peak_velocity",),
    "reduction: (baseline − candidate) / baseline × 100 %; a candidate more than twice "
    'the baseline is shown as a ratio ("3.7× the baseline\'s") instead of a large '
    "negative percentage.",
    ("rms_effort", "saturation_fraction"),
    _OTHER_METRICS,
    f"'{NOT_RECORDED}': the recording carries no such values (empty arrays are legal "
    "in ROS messages); they are never read as zeros.",
    "reduction % = (baseline − candidate) / baseline × 100; shown as '—' when "
    f"|divisor| < {FLOOR} rad (numerical noise: a perfect-model CTC settles "
    "to ~1e-13 rad), the same in metrics.json (null) and every table.",
    f"repeated runs (several seeds of a scenario and controller): mean ± "
    f"{CONFIDENCE * 100:.0f} % confidence interval, t(0.975, n − 1) · s / √n with the sample "
    "standard deviation s, and n; reductions are computed per seed pair first.",
)


def definitions_section() -> list[str]:
    """The Definitions section."""
    named = {name for item in _LAYOUT if isinstance(item, tuple) for name in item}
    bullets: list[str] = []
    for item in _LAYOUT:
        if isinstance(item, str):
            bullets.append(item)
        elif item == _OTHER_METRICS:
            bullets += [
                f"{m.definition}." for m in catalog.METRICS if m.definition and m.name not in named
            ]
        else:
            bullets.append("; ".join(catalog.metric(name).definition for name in item) + ".")
    return ["## Definitions", "", *(f"- {b}" for b in bullets), ""]
