# long: the three identify commands (excite, fit, validate) and the model document they share
"""The ``pipeline identify fit`` and ``validate`` commands: recordings in, model / verdict out.

Validation predicts each recording's torque from the model file's robot (inertials,
armature) and friction with the same regressor, on the same samples the fit would use
(same filter; joints slower than the speed threshold left out, since sticking friction
is no function of the velocity), and reports the RMS error per joint, absolute and as a
share of the RMS torque.
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.errors import IdentificationError, PipelineError
from pipeline.identify.defaults import (
    DEFAULT_CUTOFF_HZ,
    DEFAULT_MAX_CONDITION,
    DEFAULT_MIN_SPEED_RAD_S,
)
from pipeline.identify.fit import (
    FitResult,
    drive_from_prior,
    fitted_transition_speed,
    from_prior,
    identify,
    kept_rows,
    stuck_rows_method,
    violations,
)
from pipeline.identify.identity import kinematics_mismatch, robot_file_sha256
from pipeline.identify.model_file import (
    FORMAT,
    IdentifiedModel,
    TransitionSpeed,
    is_sigmoid,
    load_model,
    model_robot_document,
    speed_text,
    write_model,
)
from pipeline.identify.regressor import (
    ARMATURE,
    COULOMB,
    OFFSET,
    PER_JOINT,
    VISCOUS,
    Regressor,
    link_inertial,
    standard_parameters,
)
from pipeline.identify.samples import FILTER_ORDER, JointSamples, joint_samples
from pipeline.log.reader import ReadOptions, Recording, read_recording
from pipeline.log.robot_facts import robot_facts
from pipeline.pathlist import summarise_paths
from pipeline.robots.loaders import load_spec
from pipeline.robots.spec import RobotSpec

F64 = np.ndarray

WHOLE = ReadOptions(stream_above_bytes=1 << 62, joint_states_only=True)
"""Read every recording whole (identification needs every sample, never a decimated read),
from its joint states alone when it has no controller state (a real robot's log)."""


FIT_TRANSITION_SPEED = -1.0
"""``transition_speed_rad_s`` meaning: fit the sigmoid model's transition speed."""
FIT_TRANSITION_SPEED_PER_JOINT = -2.0
"""``transition_speed_rad_s`` meaning: fit the sigmoid model's transition speed per joint."""


def read_options(topics: Mapping[str, str] | None) -> ReadOptions:
    """:data:`WHOLE` with ``--topic ROLE=/name`` remaps."""
    return replace(WHOLE, topics=dict(topics or {}))


def require_identifiable(spec: RobotSpec, *, what: str) -> None:
    """Refuse, before any work, a robot identification cannot handle (one line).

    Raises:
        IdentificationError: a joint without link inertial (any description format works).
    """
    try:
        spec.require_dynamics(what)
    except PipelineError as err:
        raise IdentificationError(str(err)) from err


def recording_spec(recording: Recording, robot: str | None) -> RobotSpec:
    """The robot of a recording: ``robot`` if given, else the one it recorded.

    Raises:
        IdentificationError: the recording does not say, and no ``robot`` was given.
    """
    if robot:
        return load_spec(robot)
    described = _described_robot(recording)
    if described is not None:
        return described
    facts = robot_facts(recording)
    if facts.spec is not None and facts.source != "urdf":
        return facts.spec
    name = recording.metadata.get("robot") if recording.armlab_metadata else None
    if name:
        return load_spec(name)
    raise IdentificationError(
        f"{recording.source}: does not say which robot it recorded: pass --robot NAME|PATH"
    )


def _described_robot(recording: Recording) -> RobotSpec | None:
    """The URDF or MJCF robot an excitation's raw settings hold by value (an excitation's
    settings are not an episode's: read them raw); older bags name the file and its
    SHA-256, read while that file is unchanged (``robots.recorded.robot_from_dict``)."""
    if not recording.armlab_metadata:
        return None
    try:
        data = json.loads(recording.metadata.get("settings") or "{}").get("robot")
    except (ValueError, AttributeError):
        return None
    if not isinstance(data, dict) or data.get("format") in (None, "dh-yaml"):
        return None
    from pipeline.robots.recorded import robot_from_dict

    try:
        return robot_from_dict(data, where=f"{recording.source}: settings.robot")
    except PipelineError:
        return None


def _read(
    paths: Sequence[Path],
    robot: str | None,
    cutoff_hz: float,
    topics: Mapping[str, str] | None = None,
) -> tuple[RobotSpec, list[JointSamples]]:
    if not paths:
        raise IdentificationError("no recordings given")
    given = load_spec(robot) if robot else None
    if given is not None:  # before reading anything
        require_identifiable(given, what="identification")
    spec: RobotSpec | None = None
    samples = []
    for path in paths:
        recording = read_recording(Path(path), read_options(topics))
        this = given if given is not None else recording_spec(recording, None)
        if given is not None:
            _check_recorded_robot(recording, given, str(robot))
        if spec is None:
            spec = this
        elif this.joint_names != spec.joint_names or this.name != spec.name:
            raise IdentificationError(
                f"{path}: robot '{this.name}' ({', '.join(this.joint_names)}) differs from "
                f"'{spec.name}' of {paths[0]}"
            )
        samples.append(joint_samples(recording, spec, cutoff_hz=cutoff_hz))
    assert spec is not None
    return spec, samples


def _check_recorded_robot(recording: Recording, spec: RobotSpec, robot: str) -> None:
    """Refuse ``--robot`` when the recording names a robot of other kinematics (a UR5 bag
    fitted as a UR10: the pair ``validate`` refuses)."""
    facts = robot_facts(recording)
    recorded = facts.spec if facts.source != "urdf" else None
    if recorded is None:
        return  # a foreign bag: --robot is the only word on its robot
    why = kinematics_mismatch(recorded, spec)
    if why is not None:
        raise IdentificationError(
            f"{recording.source}: recorded on robot '{recorded.name}', not on --robot "
            f"{robot} ('{spec.name}': {why}); fit it as the robot it recorded (omit --robot)"
        )


def _check_efforts(spec: RobotSpec, samples: Sequence[JointSamples]) -> None:
    """Refuse efforts that never change on some joint over all recordings (all zero, or
    a constant: a driver that measures no torque fills in a fixed value)."""
    tau = np.vstack([s.tau_nm for s in samples])
    flat = [j for j in range(spec.dof) if float(np.ptp(tau[:, j])) == 0.0]
    if not flat:
        return
    names = ", ".join(spec.joint_names[j] for j in flat)
    values = sorted({float(tau[0, j]) for j in flat})
    what = (
        "all zero" if values == [0.0] else f"constant ({', '.join(f'{v:g}' for v in values)} N m)"
    )
    where = summarise_paths([s.source for s in samples], what="recording")
    raise IdentificationError(
        f"{where}: /joint_states effort of {names} is {what} in every sample: no torque "
        "was measured there; identification needs the applied torque"
    )


def identified_spec(
    spec: RobotSpec,
    theta: np.ndarray,
    *,
    identified_armature: bool = True,
    prior_armature: Sequence[str] = (),
) -> RobotSpec:
    """``spec`` with the inertials and armature of standard parameters ``theta``
    (``identified_armature=False``: the description's armature kept; ``prior_armature``:
    joints whose armature the data cannot separate, said so in ``armature_source``)."""
    joints = tuple(
        replace(
            joint,
            inertial=link_inertial(spec, j, theta[PER_JOINT * j : PER_JOINT * j + 10]),
            armature=float(theta[PER_JOINT * j + ARMATURE]),
        )
        for j, joint in enumerate(spec.joints)
    )
    source = (
        "identified from recordings (pipeline identify fit)"
        + (
            "; from the prior (CAD, not separable by the data): " + ", ".join(prior_armature)
            if prior_armature
            else ""
        )
        if identified_armature
        else spec.armature_source or "the description's (link-side torque: not observable)"
    )
    return replace(spec, joints=joints, armature_source=source)


def _floats(values: np.ndarray | Sequence[float]) -> list[float]:
    return [float(x) for x in values]


def sample_counts(s: JointSamples) -> dict[str, Any]:
    """What a recording's samples needed: repeats dropped, resampling (see :mod:`.samples`)."""
    return {
        "repeated_stamps_dropped": s.repeated_stamps,
        "repeated_values_dropped": s.repeated_values,
        "resampled": s.resampled,
        "stamp_period_ms": [round(x * 1e3, 6) for x in s.period_range_s],
    }


def friction_document(fit: FitResult) -> dict[str, Any]:
    """The model file's ``friction`` of an identification."""
    theta = fit.theta
    v_s = fit.transition_speed_rad_s
    return {
        "model": "sigmoid" if is_sigmoid(v_s) else "coulomb",
        "transition_speed_rad_s": list(v_s) if isinstance(v_s, tuple) else v_s,
        "coulomb_nm": _floats(theta[COULOMB::PER_JOINT]),
        "viscous_nm_s_rad": _floats(theta[VISCOUS::PER_JOINT]),
        "offset_nm": _floats(theta[OFFSET::PER_JOINT]),
    }


def model_document(
    spec: RobotSpec,
    fit: FitResult,
    samples: Sequence[JointSamples],
    *,
    method: Mapping[str, Any],
) -> dict[str, Any]:
    """The ``MODEL.yaml`` content of an identification.

    Args:
        spec: the robot identified (the CAD model).
        fit: the identification.
        samples: the recordings it used (paths and SHA-256).
        method: how the samples were made (filter, cutoff, speed threshold).
    """
    theta = fit.theta
    rel = np.abs(fit.std_error) / np.maximum(np.abs(fit.beta_wls), 1e-12) * 100
    link = fit.torque_side == "link"
    drive = drive_from_prior(spec, fit.base)
    prior_armature = [n.removesuffix(".armature") for n in drive if n.endswith(".armature")]
    return {
        "format": FORMAT,
        **model_robot_document(
            identified_spec(
                spec, theta, identified_armature=not link, prior_armature=prior_armature
            ),
            armature_from={
                j: "description" if link else "prior" if j in prior_armature else "data"
                for j in spec.joint_names
            },
        ),
        "friction": friction_document(fit),
        "torque_side": fit.torque_side,
        "identification": {
            "robot": spec.name,
            "robot_source": spec.source,
            "robot_format": spec.format,
            "torque_side": {
                "assumed": fit.torque_side,
                "why": fit.torque_side_reason,
                "armature": (
                    "not observable (torque sensed on the link side): the description's "
                    "value is kept"
                    if link
                    else "identified (torque includes the rotor's inertia)"
                    + (
                        ", except " + ", ".join(prior_armature) + ": from the prior"
                        if prior_armature
                        else ""
                    )
                ),
            },
            "from_prior": {
                "why": "the data cannot separate these standard parameters from others "
                "(not in the row space of the base projection): their values are the CAD "
                "prior's, moved only by their share of a combination's correction; never "
                "identified",
                "drive": list(drive_from_prior(spec, fit.base)),
                "inertial": [n for n in from_prior(spec, fit.base) if n not in drive],
            },
            "robot_sha256": robot_file_sha256(spec),
            "recordings": [
                {"path": s.source, "sha256": s.sha256, "ground_truth": s.truth, **sample_counts(s)}
                for s in samples
            ],
            "method": {
                "regressor": "pinocchio computeJointTorqueRegressor + armature (qdd"
                + (", left out: link-side torque" if link else "")
                + ") + friction (Coulomb "
                + (
                    f"tanh(qd / {speed_text(fit.transition_speed_rad_s)} rad/s)"
                    if is_sigmoid(fit.transition_speed_rad_s)
                    else "sign(qd)"
                )
                + ", viscous qd, sensor offset 1) per joint",
                "base_parameters": "QR with column pivoting of the regressor stacked over "
                "random states",
                "estimator": "weighted least squares, weights 1/sigma_j from an OLS residual",
                "std_error": "Newey-West (HAC) sandwich over the weighted scores summed per "
                f"instant, Bartlett kernel, {fit.hac_lags} lags (Andrews' AR(1) plug-in rule)",
                "physical": "log-Cholesky pseudo-inertia per link (Rucker & Wensing 2022), "
                "armature and friction >= 0; Levenberg-Marquardt from the CAD model",
                **dict(method),
            },
            "equations": fit.rows,
            "condition_number": fit.condition_number,
            "condition_number_scaled": fit.condition_number_scaled,
            "projection_cost": fit.projection_cost,
            "joint_sigma_nm": _floats(fit.joint_sigma_nm),
            "residual_rms_nm": _floats(fit.residual_rms_nm),
            "torque_rms_nm": _floats(fit.torque_rms_nm),
            "base_parameters": [
                {
                    "name": name,
                    "wls": float(b),
                    "std_error": float(se),
                    "std_error_iid": float(si),
                    "rel_std_error_pct": float(r),
                    "physical": float(p),
                    "cad": float(c),
                }
                for name, b, se, si, r, p, c in zip(
                    fit.base.names,
                    fit.beta_wls,
                    fit.std_error,
                    fit.std_error_iid if fit.std_error_iid is not None else fit.std_error,
                    rel,
                    fit.beta,
                    fit.base.of(fit.theta_cad),
                    strict=True,
                )
            ],
        },
    }


def fit_command(
    paths: Sequence[Path],
    *,
    out: Path,
    robot: str | None = None,
    cutoff_hz: float = DEFAULT_CUTOFF_HZ,
    min_speed_rad_s: float = DEFAULT_MIN_SPEED_RAD_S,
    max_condition: float = DEFAULT_MAX_CONDITION,
    topics: Mapping[str, str] | None = None,
    transition_speed_rad_s: TransitionSpeed = 0.0,
    torque_side: str = "motor",
) -> dict[str, Any]:
    """Identify from ``paths``, write ``out`` (MODEL.yaml); the JSON summary.

    Args:
        topics: role -> topic remaps (``--topic joint_states=/name``).
        transition_speed_rad_s: 0: Coulomb friction ``sign(qd)``; > 0: ``tanh(qd / v_s)``;
            :data:`FIT_TRANSITION_SPEED`: ``tanh`` with the best-fitting ``v_s``;
            :data:`FIT_TRANSITION_SPEED_PER_JOINT`: each joint's best-fitting ``v_s``;
            a tuple: one ``v_s`` per joint.
        torque_side: ``motor``, ``link`` or ``auto`` (:func:`pipeline.identify.fit.identify`).

    Raises:
        PipelineError: unreadable recordings, unfit data (one line), unwritable output.
    """
    from pipeline.fsutil import check_output_file

    wall0 = time.perf_counter()
    check_output_file(Path(out))  # a device, FIFO or folder: refused before the fit
    fitted_speed = transition_speed_rad_s in (FIT_TRANSITION_SPEED, FIT_TRANSITION_SPEED_PER_JOINT)
    per_joint = transition_speed_rad_s == FIT_TRANSITION_SPEED_PER_JOINT
    check_fit_options(
        torque_side=torque_side,
        transition_speed_rad_s=0.0 if fitted_speed else transition_speed_rad_s,
    )
    spec, samples = _read(paths, robot, cutoff_hz, topics)
    require_identifiable(spec, what="identification")
    _check_efforts(spec, samples)
    transition: dict[str, Any] = {}
    if fitted_speed:
        transition_speed_rad_s, costs = fitted_transition_speed(
            spec, samples, min_speed_rad_s=min_speed_rad_s, per_joint=per_joint
        )
        transition = {
            "transition_speed": "fitted: least-squares residual over candidate speeds"
            + (", then per joint (coordinate search)" if per_joint else ""),
            "transition_speed_costs": {f"{k:g}": v for k, v in costs.items()},
        }
    fit = identify(
        spec, samples, min_speed_rad_s=min_speed_rad_s, max_condition=max_condition,
        transition_speed_rad_s=transition_speed_rad_s, torque_side=torque_side,
    )  # fmt: skip
    bad = violations(spec, fit.theta)
    if bad:  # cannot happen by construction; a guard against a solver returning nonsense
        raise IdentificationError(f"the identified model is not physical: {bad[0]}")
    method = {
        "filter": (
            {"type": "butterworth", "order": FILTER_ORDER, "zero_phase": True,
             "cutoff_hz": cutoff_hz}
            if cutoff_hz > 0
            else {"type": "none", "acceleration": "forward difference of recorded velocity"}
        ),
        **({"stuck_rows": stuck_rows_method()} if cutoff_hz > 0 else {}),
        "min_speed_rad_s": min_speed_rad_s,
        "max_condition": max_condition,
        **transition,
    }  # fmt: skip
    write_model(out, model_document(spec, fit, samples, method=method))
    rel = np.abs(fit.std_error) / np.maximum(np.abs(fit.beta_wls), 1e-12) * 100
    return {
        "model": str(out),
        "robot": spec.name,
        "recordings": [{"path": s.source, "sha256": s.sha256} for s in samples],
        "equations": fit.rows,
        "base_parameters": fit.base.rank,
        "condition_number": fit.condition_number,
        "condition_number_scaled": fit.condition_number_scaled,
        "projection_cost": fit.projection_cost,
        "max_rel_std_error_pct": float(rel.max()),
        "std_error": f"Newey-West, {fit.hac_lags} lags",
        "from_prior": list(drive_from_prior(spec, fit.base)),
        "residual_rms_nm": [float(x) for x in fit.residual_rms_nm],
        "torque_rms_nm": [float(x) for x in fit.torque_rms_nm],
        "joints": list(spec.joint_names),
        "torque_side": fit.torque_side,
        "torque_side_reason": fit.torque_side_reason,
        "friction_model": "sigmoid" if is_sigmoid(transition_speed_rad_s) else "coulomb",
        "transition_speed_rad_s": (
            list(transition_speed_rad_s)
            if isinstance(transition_speed_rad_s, tuple)
            else transition_speed_rad_s
        ),
        "repeated_stamps_dropped": sum(s.repeated_stamps for s in samples),
        "repeated_values_dropped": sum(s.repeated_values for s in samples),
        "resampled": [s.source for s in samples if s.resampled],
        "offset_nm": _floats(fit.theta[OFFSET::PER_JOINT]),
        "wall_s": time.perf_counter() - wall0,
    }


def check_fit_options(*, torque_side: str, transition_speed_rad_s: TransitionSpeed) -> None:
    """Refuse bad ``--torque-side`` / ``--friction`` values before reading anything."""
    from pipeline.identify.fit import TORQUE_SIDES

    if torque_side not in TORQUE_SIDES:
        raise IdentificationError(
            f"--torque-side: expected one of {', '.join(TORQUE_SIDES)}, got {torque_side!r}"
        )
    speeds = np.asarray(transition_speed_rad_s, dtype=float)
    if not (np.all(np.isfinite(speeds)) and np.all(speeds >= 0)):
        raise IdentificationError(
            f"--transition-speed: expected a speed >= 0 rad/s, got {transition_speed_rad_s!r}"
        )


@dataclass(frozen=True)
class Prediction:
    """Measured and predicted torque of one recording (rows: samples; slow joints NaN)."""

    source: str
    times_s: F64
    measured_nm: F64
    predicted_nm: F64


def model_parameters(model: IdentifiedModel) -> F64:
    """The standard parameter vector of a model file (inertials, armature, friction)."""
    f = model.friction
    return standard_parameters(  # the armature is left out of a link-side model's regressor
        model.spec,
        coulomb_nm=np.asarray(f.coulomb_nm),
        viscous_nm_s_rad=np.asarray(f.viscous_nm_s_rad),
        offset_nm=np.asarray(f.offset_nm),
    )


def predict(model: IdentifiedModel, samples: JointSamples, *, min_speed_rad_s: float) -> Prediction:
    """The model's torque on a recording's samples (the joint samples the fit would leave
    out, slow or near a stuck joint, set to NaN)."""
    theta = model_parameters(model)
    n, dof = samples.q.shape
    reg = Regressor(
        model.spec,
        transition_speed_rad_s=model.friction.transition_speed_rad_s,
        armature=model.torque_side == "motor",
    )
    coulomb = samples.coulomb(model.friction.transition_speed_rad_s)
    y = reg.stacked(samples.q, samples.qd, samples.qdd, coulomb=coulomb)
    predicted = (y @ theta).reshape(n, dof)
    slow = ~kept_rows(samples, min_speed_rad_s).reshape(n, dof)  # the rows fit leaves out
    measured = samples.tau_nm.copy()
    measured[slow] = np.nan
    predicted[slow] = np.nan
    return Prediction(samples.source, np.arange(n) * samples.dt_s, measured, predicted)


def validate_command(
    model_path: Path,
    paths: Sequence[Path],
    *,
    figure: Path | None = None,
    cutoff_hz: float | None = None,
    min_speed_rad_s: float | None = None,
    topics: Mapping[str, str] | None = None,
    robot: str | None = None,
) -> dict[str, Any]:
    """Torque RMS error per joint of ``model_path`` on ``paths``; a figure; the summary.

    The filter and speed threshold default to the model's own (its ``identification``).

    Args:
        topics: role -> topic remaps (``--topic joint_states=/name``).
        robot: the robot the model applies to (default: the description it names).

    Raises:
        PipelineError: a bad model file, unreadable recordings, a recording of another robot.
    """
    from pipeline.fsutil import check_output_file

    model = load_model(model_path, robot=load_spec(robot) if robot else None)
    check_output_file(figure or Path(model_path).with_suffix(".validation.png"))
    method = model.identification.get("method", {})
    if cutoff_hz is None:
        filt = method.get("filter", {}) if isinstance(method, dict) else {}
        cutoff_hz = float(filt.get("cutoff_hz", 0.0)) if filt.get("type") != "none" else 0.0
    if min_speed_rad_s is None:
        min_speed_rad_s = float(method.get("min_speed_rad_s", DEFAULT_MIN_SPEED_RAD_S))
    if not paths:
        raise IdentificationError("no recordings given")
    predictions = []
    sampled = []
    for path in paths:
        recording = read_recording(Path(path), read_options(topics))
        recorded = recording.metadata.get("robot") if recording.armlab_metadata else None
        if recorded and recorded != model.spec.name:
            raise IdentificationError(
                f"{path}: a recording of robot '{recorded}', the model is of '{model.spec.name}'"
            )
        samples = joint_samples(recording, model.spec, cutoff_hz=cutoff_hz)
        sampled.append(samples)
        predictions.append(predict(model, samples, min_speed_rad_s=min_speed_rad_s))
    measured = np.concatenate([p.measured_nm for p in predictions])
    predicted = np.concatenate([p.predicted_nm for p in predictions])
    err = predicted - measured
    rms_err = np.sqrt(np.nanmean(err**2, axis=0))
    rms_tau = np.sqrt(np.nanmean(measured**2, axis=0))
    figure = figure or Path(model_path).with_suffix(".validation.png")
    write_figure(figure, model.spec, predictions[0])
    return {
        "model": str(model_path),
        "robot": model.spec.name,
        "recordings": [str(p) for p in paths],
        "joints": list(model.spec.joint_names),
        "rms_error_nm": [float(x) for x in rms_err],
        "rms_torque_nm": [float(x) for x in rms_tau],
        "rms_error_pct": [float(x) for x in 100 * rms_err / np.maximum(rms_tau, 1e-12)],
        "samples": int(measured.shape[0]),
        "cutoff_hz": cutoff_hz,
        "min_speed_rad_s": min_speed_rad_s,
        "repeated_stamps_dropped": sum(s.repeated_stamps for s in sampled),
        "repeated_values_dropped": sum(s.repeated_values for s in sampled),
        "resampled": [s.source for s in sampled if s.resampled],
        "figure": str(figure),
    }


def write_figure(path: Path, spec: RobotSpec, prediction: Prediction) -> None:
    """Predicted vs measured torque per joint, over time (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dof = spec.dof
    fig, axes = plt.subplots(dof, 1, figsize=(9, 1.6 * dof + 0.8), sharex=True, squeeze=False)
    for j, ax in enumerate(axes[:, 0]):
        ax.plot(prediction.times_s, prediction.measured_nm[:, j], lw=1.0, label="measured")
        ax.plot(prediction.times_s, prediction.predicted_nm[:, j], lw=0.8, ls="--",
                label="predicted")  # fmt: skip
        ax.set_ylabel(f"{spec.joint_names[j]}\n[N m]", fontsize=7)
        ax.tick_params(labelsize=7)
    axes[0, 0].legend(fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"torque: identified model vs {Path(prediction.source).name}", fontsize=9)
    fig.tight_layout()
    from pipeline.fsutil import atomic_write_bytes

    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
        atomic_write_bytes(Path(path), buf.getvalue())
    except OSError as err:
        raise PipelineError(f"{path}: cannot write the figure ({err.strerror or err})") from err
    finally:
        plt.close(fig)
