"""``pipeline identify``: excite, fit, validate (a Typer sub-app; errors reach the main CLI's
one-line handler as :class:`pipeline.errors.PipelineError`)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from pipeline.identify.defaults import (
    DEFAULT_BUDGET_S,
    DEFAULT_CUTOFF_HZ,
    DEFAULT_EVALUATIONS,
    DEFAULT_MAX_CONDITION,
    DEFAULT_MIN_SPEED_RAD_S,
)

identify_app = typer.Typer(
    help=(
        "Identify the arm's dynamics from recordings: design and record an excitation, "
        "fit inertials, armature and friction (MODEL.yaml), validate on other recordings."
    ),
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
)


def _emit(summary: dict[str, Any], *, as_json: bool, lines: list[str]) -> None:
    if as_json:
        sys.stdout.write(json.dumps(summary, indent=2) + "\n")
    else:
        sys.stdout.write("\n".join(lines) + "\n")


def _floats(text: str, option: str) -> list[float]:
    try:
        return [float(x) for x in text.replace(" ", "").split(",") if x]
    except ValueError as err:
        from pipeline.errors import IdentificationError

        raise IdentificationError(
            f"{option}: expected comma-separated numbers, got {text!r}"
        ) from err


def _row(values: list[float], fmt: str) -> str:
    return " ".join(format(v, fmt) for v in values)


TOPIC_HELP = (
    "ROLE=/name: the topic serving a role (joint_states, ground_truth, ...) when it is "
    "neither ours nor the only one of its message type, as on `pipeline report`. Repeatable."
)


def _topics(items: list[str] | None) -> dict[str, str]:
    from pipeline.cli.report_cmd import topic_remaps

    return topic_remaps(items or [])


FRICTION_MODELS = ("coulomb", "sigmoid")
DEFAULT_TRANSITION_SPEED_RAD_S = 0.1
"""The sigmoid model's default transition speed (real arms: about 0.05-0.2 rad/s)."""


def _speed_text(speed: float | list[float]) -> str:
    """A transition speed for the summary line: ``0.1`` or, per joint, ``0.2/0.05/...``."""
    return "/".join(f"{v:g}" for v in speed) if isinstance(speed, list) else f"{speed:g}"


def _transition_speed(friction: str, text: str | None) -> float:
    """``--friction`` and ``--transition-speed`` -> the fit's ``transition_speed_rad_s``
    (0: Coulomb; > 0: sigmoid; ``FIT_TRANSITION_SPEED``: sigmoid, speed fitted)."""
    from pipeline.errors import IdentificationError
    from pipeline.identify.stage import FIT_TRANSITION_SPEED, FIT_TRANSITION_SPEED_PER_JOINT

    if friction not in FRICTION_MODELS:
        raise IdentificationError(
            f"--friction: expected one of {', '.join(FRICTION_MODELS)}, got {friction!r}"
        )
    if friction == "coulomb":
        if text is not None:
            raise IdentificationError("--transition-speed: only with --friction sigmoid")
        return 0.0
    if text is None:
        return DEFAULT_TRANSITION_SPEED_RAD_S
    if text.strip() == "auto":
        return FIT_TRANSITION_SPEED
    if text.strip() == "per-joint":
        return FIT_TRANSITION_SPEED_PER_JOINT
    try:
        value = float(text)
    except ValueError as err:
        raise IdentificationError(
            f"--transition-speed: expected a speed [rad/s], auto or per-joint, got {text!r}"
        ) from err
    if not value > 0:
        raise IdentificationError(f"--transition-speed: expected a speed > 0 rad/s, got {value!r}")
    return value


@identify_app.command("fit")
def fit_cmd(
    recordings: Annotated[list[Path], typer.Argument(help="Recordings (rosbag2 folders, .mcap).")],
    out: Annotated[Path, typer.Option("--out", help="The model file to write (MODEL.yaml).")],
    robot: Annotated[
        str | None,
        typer.Option("--robot", help="Robot name or YAML (default: the one recorded)."),
    ] = None,
    cutoff_hz: Annotated[
        float,
        typer.Option(
            "--cutoff-hz",
            help="Zero-phase Butterworth cutoff [Hz]; 0: no filter, recorded velocities "
            "and their forward difference (exact on noise-free simulated data).",
        ),
    ] = DEFAULT_CUTOFF_HZ,
    min_speed: Annotated[
        float,
        typer.Option("--min-speed", help="Leave out joint samples slower than this \\[rad/s]."),
    ] = DEFAULT_MIN_SPEED_RAD_S,
    max_condition: Annotated[
        float,
        typer.Option(
            "--max-condition",
            help="Refuse a regressor (unit-norm columns) whose pivots fall below "
            "1/this of the largest (unexcited parameters).",
        ),
    ] = DEFAULT_MAX_CONDITION,
    topic: Annotated[list[str] | None, typer.Option("--topic", help=TOPIC_HELP)] = None,
    friction: Annotated[
        str,
        typer.Option(
            "--friction",
            help="Friction model: coulomb (fc sign(qd) + fv qd) or sigmoid (fc tanh(qd / v_s) "
            "+ fv qd, a sign change over about v_s).",
        ),
    ] = "coulomb",
    transition_speed: Annotated[
        str | None,
        typer.Option(
            "--transition-speed",
            help="The sigmoid model's v_s \\[rad/s], or auto: the best fit of 0.01, 0.02, "
            "0.05, 0.1, 0.15, 0.2, 0.3, 0.5, or per-joint: each joint's best fit of "
            f"0.01-0.7 (default {DEFAULT_TRANSITION_SPEED_RAD_S:g}).",
        ),
    ] = None,
    torque_side: Annotated[
        str,
        typer.Option(
            "--torque-side",
            help="Where the torque is sensed: motor (includes the rotor: armature "
            "identified), link (after the gearbox: armature not observable, the "
            "description's kept) or auto (link when no armature shows in the data).",
        ),
    ] = "motor",
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Identify base parameters (WLS, standard errors), make them physical, write MODEL.yaml.

    A bag with /joint_states (position, velocity, effort) is enough: no controller state,
    no metadata (pass --robot). Repeated samples are dropped, uneven stamps resampled.
    """
    from pipeline.identify.stage import fit_command

    s = fit_command(
        recordings,
        out=out,
        robot=robot,
        cutoff_hz=cutoff_hz,
        min_speed_rad_s=min_speed,
        max_condition=max_condition,
        topics=_topics(topic),
        transition_speed_rad_s=_transition_speed(friction, transition_speed),
        torque_side=torque_side,
    )
    _emit(
        s,
        as_json=as_json,
        lines=[
            f"identified {s['base_parameters']} base parameters of {s['robot']} from "
            f"{s['equations']} equations in {s['wall_s']:.1f} s",
            f"samples: {s['repeated_stamps_dropped']} repeated stamps and "
            f"{s['repeated_values_dropped']} repeated values dropped; "
            f"{len(s['resampled'])} of {len(s['recordings'])} recording(s) resampled "
            "(uneven stamps)",
            f"friction {s['friction_model']}"
            + (
                f" (transition speed {_speed_text(s['transition_speed_rad_s'])} rad/s)"
                if s["friction_model"] == "sigmoid"
                else ""
            )
            + f"; torque side {s['torque_side']} ({s['torque_side_reason']})",
            f"condition number {s['condition_number']:.4g} (unit-norm columns "
            f"{s['condition_number_scaled']:.4g}); largest relative standard error "
            f"{s['max_rel_std_error_pct']:.3g} % ({s['std_error']})",
            "from the prior (the data cannot separate them; not identified): "
            + (", ".join(s["from_prior"]) or "none"),
            f"residual RMS [N m]: {_row(s['residual_rms_nm'], '.3g')}",
            f"torque RMS   [N m]: {_row(s['torque_rms_nm'], '.3g')}",
            f"sensor offset [N m]: {_row(s['offset_nm'], '.3g')}",
            f"wrote {s['model']}",
        ],
    )


@identify_app.command("validate")
def validate_cmd(
    model: Annotated[Path, typer.Argument(help="The model file (MODEL.yaml).")],
    recordings: Annotated[list[Path], typer.Argument(help="Recordings not used in the fit.")],
    figure: Annotated[
        Path | None,
        typer.Option("--figure", help="Predicted-vs-measured PNG (default: next to MODEL)."),
    ] = None,
    topic: Annotated[list[str] | None, typer.Option("--topic", help=TOPIC_HELP)] = None,
    robot: Annotated[
        str | None,
        typer.Option(
            "--robot", help="Robot name or file the model applies to (default: the one it names)."
        ),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Torque RMS error per joint of MODEL on other recordings, absolute and % of RMS torque.

    Repeated samples are dropped and uneven stamps resampled, as in fit (and reported).
    """
    from pipeline.identify.stage import validate_command

    s = validate_command(model, recordings, figure=figure, topics=_topics(topic), robot=robot)
    lines = [
        f"samples: {s['repeated_stamps_dropped']} repeated stamps and "
        f"{s['repeated_values_dropped']} repeated values dropped; "
        f"{len(s['resampled'])} of {len(s['recordings'])} recording(s) resampled "
        "(uneven stamps)",
        f"{'joint':<22} {'RMS error [N m]':>16} {'RMS torque [N m]':>17} {'error %':>8}",
    ]
    for name, e, t, p in zip(
        s["joints"], s["rms_error_nm"], s["rms_torque_nm"], s["rms_error_pct"], strict=True
    ):
        lines.append(f"{name:<22} {e:>16.4g} {t:>17.4g} {p:>8.3g}")
    lines.append(f"wrote {s['figure']}")
    _emit(s, as_json=as_json, lines=lines)


@identify_app.command("excite")
def excite_cmd(
    params: Annotated[Path, typer.Option("--params", help="The params file.")] = Path(
        "params.yaml"
    ),
    scenario: Annotated[
        str, typer.Option("--scenario", help="Scenario: robot, mid posture, plant.")
    ] = "paper",
    seed: Annotated[int, typer.Option("--seed", help="Seed of the plant draw and noise.")] = 0,
    variant: Annotated[int, typer.Option("--variant", help="Seed of the excitation design.")] = 0,
    out: Annotated[Path, typer.Option("--out", help="The recording to write (a folder).")] = Path(
        "recordings/excitation"
    ),
    controller: Annotated[
        str | None,
        typer.Option("--controller", help="Controller tracking it (default: ctc)."),
    ] = None,
    harmonics: Annotated[int, typer.Option("--harmonics", help="Harmonics per joint.")] = 5,
    base_frequency_hz: Annotated[
        float, typer.Option("--base-frequency-hz", help="Fundamental frequency [Hz].")
    ] = 0.1,
    periods: Annotated[int, typer.Option("--periods", help="Periods recorded.")] = 2,
    span_rad: Annotated[
        float, typer.Option("--span-rad", help="Largest excursion from the mid posture \\[rad].")
    ] = 1.0,
    evaluations: Annotated[
        int,
        typer.Option(
            "--evaluations",
            min=1,
            help="Objective evaluations the design spends (L-BFGS-B restarts until spent; "
            "a gradient costs 1 + the free coefficients). A count, not a time: the same "
            "design and recording on any machine. Default: about 25 s for the UR5 on a "
            "quiet machine.",
        ),
    ] = DEFAULT_EVALUATIONS,
    budget_s: Annotated[
        float,
        typer.Option(
            "--budget-s",
            min=0.001,
            help="Wall-clock safety cap of the design \\[s]: past it excite fails (it never "
            "records a design cut short by machine load).",
        ),
    ] = DEFAULT_BUDGET_S,
    force: Annotated[bool, typer.Option("--force", help="Overwrite the recording.")] = False,
    mid: Annotated[
        str | None,
        typer.Option(
            "--mid",
            help="Mid posture, comma-separated \\[rad] (default: the scenario's start); "
            "a bent arm excites better than a stretched one.",
        ),
    ] = None,
    export: Annotated[
        Path | None,
        typer.Option("--export", help="Also write the trajectory as CSV (1 kHz) for a robot."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print a JSON summary.")] = False,
) -> None:
    """Design excitation K (Fourier series, within limits, collision-free); record it on S."""
    from pipeline.identify.excitation import record_excitation

    s = record_excitation(
        params,
        scenario_name=scenario,
        seed=seed,
        variant=variant,
        out=out,
        controller_name=controller,
        harmonics=harmonics,
        base_frequency_hz=base_frequency_hz,
        periods=periods,
        span_rad=span_rad,
        evaluations=evaluations,
        budget_s=budget_s,
        force=force,
        export=export,
        mid_posture=_floats(mid, "--mid") if mid else None,
    )
    _emit(
        s,
        as_json=as_json,
        lines=[
            f"excitation {variant}: condition number {s['condition_number']:.4g} (unit-norm "
            f"columns {s['condition_number_scaled']:.4g}), designed in "
            f"{s['design_evaluations']} evaluations ({s['design_wall_s']:.1f} s)",
            f"recorded {s['duration_s']:.0f} s on scenario {scenario}, seed {seed}, "
            f"controller {s['controller']}: {s['recording']}",
        ],
    )
