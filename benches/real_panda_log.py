"""A published real log we did not write: Gaz et al.'s Franka Emika Panda excitation run.

Material (not in this repo; GPL-3.0, fetch it yourself):
github.com/marcocognetti/FrankaEmikaPandaDynModel, commit 24d85ce. ``--log-dir`` is
``matlab/data/Exciting_Traj/Trajectory_1/rbt_log`` (``exciting_traj_{time,positions,
velocity,torques}.txt``: one number a line, 7 a sample; 20544 samples over 21.0 s, stamps
0.7 to 8.8 ms apart, 1255 samples repeating the previous one), ``--model-dir`` is
``matlab/dyn_model_panda`` (the authors' model: ``get_MassMatrix.m``,
``get_CoriolisVector.m``, ``get_GravityVector.m``, ``get_FrictionTorque.m``).

What it does, as a user would:

1. Writes the log as ROS 2 bags with ``rosbags`` (MCAP): only ``/joint_states`` (position,
   velocity, the measured link-side torque ``tau_J`` as effort) with the log's own stamps,
   repeats kept. The first 70 % of the run's duration goes to ``fit/``, the last 30 % to
   ``held_out/`` (a time split: the excitation is not periodic within the log).
2. ``pipeline identify fit fit/ --robot panda --friction sigmoid --torque-side link``
   (Franka's torque sensors sit after the gearbox: the rotor inertia is not in ``tau_J``),
   then ``pipeline identify validate MODEL held_out/``: our held-out RMS error per joint.
3. The authors' model on the SAME held-out samples: ``M(q) qdd + c(q, qd) + g(q) +
   tau_f(qd)`` evaluated from their MATLAB files, translated to NumPy at run time (a
   ``python/panda_dyn_model.py`` exists only in unmerged pull request #8, as a stub loading
   a C++ extension to be compiled first: not importable as fetched). A second, independent
   evaluation: Pinocchio's RNEA with their feasible parameters
   (``pipeline/model/published.py``'s ``gaz_links(hand=False)``) plus their sigmoid friction.
   Checks of the translation, every run: M and g equal ``tests/model/gaz_reference.py`` at
   its three configurations (to its 10 digits); c equals the Christoffel form of their M
   (central differences, 1e-6 N m).
   Samples: ``pipeline.identify.samples.joint_samples`` at the model's cutoff, i.e. the
   zero-phase Butterworth (5 Hz) of ``fit``/``validate``: filtered q, recorded velocity
   filtered, its central difference for qdd, filtered torque, decimated; joint samples
   slower than the model's ``min_speed`` or near a stuck joint left out for both (and for
   the offset's mean on the fit part), exactly as ``fit``/``validate`` do
   (``pipeline.identify.fit.kept_rows``).

Prints one JSON object, then a Markdown table.

Usage: python benches/real_panda_log.py --log-dir DIR --model-dir DIR
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

T0_NS = 1_700_000_000_000_000_000  # a wall-clock-like origin, as a driver's stamps
FIT_SHARE = 0.7
JOINTS = [f"panda_joint{i}" for i in range(1, 8)]


def read_log(log_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Stamps [s], q [rad], qd [rad/s], tau_J [N m] of the authors' text files."""

    def column(name: str) -> np.ndarray:
        return np.loadtxt(log_dir / f"exciting_traj_{name}.txt", dtype=np.float64)

    t = column("time")
    q, qd, tau = (column(n).reshape(-1, 7) for n in ("positions", "velocity", "torques"))
    if not (q.shape == qd.shape == tau.shape == (t.size, 7)):
        raise SystemExit(f"error: {log_dir}: sizes differ ({t.size} stamps, {q.shape} positions)")
    return t, q, qd, tau


def write_bag(path: Path, t_s: np.ndarray, q: np.ndarray, qd: np.ndarray, tau: np.ndarray) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    types = store.types
    header_t, time_t = types["std_msgs/msg/Header"], types["builtin_interfaces/msg/Time"]
    js_t = types["sensor_msgs/msg/JointState"]
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/joint_states", js_t.__msgtype__, typestore=store)
        for k in range(t_s.size):
            ns = T0_NS + round(float(t_s[k]) * 1e9)
            header = header_t(stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="")
            msg = js_t(header=header, name=JOINTS, position=q[k], velocity=qd[k], effort=tau[k])
            w.write(conn, ns, store.serialize_cdr(msg, js_t.__msgtype__))


# --- the authors' MATLAB model, translated at run time --------------------------------

_ARRAYS = ("q", "dq", "Bstack_hat")


def _py(expr: str) -> str:
    expr = expr.replace(".^", "**").replace(".*", "*").replace("./", "/")
    return re.sub(
        r"\b(" + "|".join(_ARRAYS) + r")\((\d+)\)", lambda m: f"{m[1]}[{int(m[2]) - 1}]", expr
    )


def _matrix(body: str) -> str:
    """``[a;b]`` / ``[a,b;c,d]`` (no brackets inside) -> a nested Python list literal."""
    rows = [r for r in body.split(";") if r.strip()]
    if not any("," in r for r in rows):  # a column vector: a flat list
        return "[" + ",".join(_py(r) for r in rows) + "]"
    return "[" + ",".join("[" + _py(r) + "]" for r in rows) + "]"


def translate(path: Path) -> tuple[str, str]:
    """(Python source, output name) of one generated MATLAB function of q (and dq)."""
    text = path.read_text()
    text = "\n".join(line.split("%", 1)[0] for line in text.splitlines())
    text = text.replace("...\n", " ")
    head = re.search(r"function\s+(\w+)\s*=\s*\w+\([^)]*\)", text)
    if head is None:
        raise SystemExit(f"error: {path}: no 'function OUT = NAME(...)' line")
    out = head[1]
    lines = []
    for statement in text[head.end() :].split(";\n"):
        statement = " ".join(statement.split())
        if not statement:
            continue
        if statement.startswith("end"):
            break
        name, _, expr = statement.partition("=")
        name, expr = name.strip(), expr.strip().rstrip(";")
        if expr.startswith("["):
            lines.append(f"{name} = {_matrix(expr[1:-1])}")
        else:
            lines.append(f"{name} = {_py(expr)}")
    return "\n".join(lines), out


class MatlabModel:
    """``get_MassMatrix``, ``get_CoriolisVector``, ``get_GravityVector``,
    ``get_FrictionTorque`` of the authors, evaluated vectorized over samples."""

    def __init__(self, model_dir: Path) -> None:
        self.code = {}
        for name in ("MassMatrix", "CoriolisVector", "GravityVector"):
            src, out = translate(model_dir / f"get_{name}.m")
            self.code[name] = (compile(src, f"get_{name}.m (translated)", "exec"), out)
        fp = (model_dir / "get_FrictionTorque.m").read_text()
        block = re.search(r"fp\s*=\s*\[(.*?)\];", fp, re.S)
        if block is None:
            raise SystemExit(f"error: {model_dir}/get_FrictionTorque.m: no 'fp = [...]' matrix")
        rows = [r for r in block[1].replace("...", "").split(";") if r.strip()]
        self.fp = np.array([[float(x) for x in r.split(",")] for r in rows])  # (4, 7)

    def _eval(self, name: str, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
        code, out = self.code[name]
        scope: dict[str, object] = {"sin": np.sin, "cos": np.cos, "sqrt": np.sqrt}
        scope.update(q=q.T, dq=dq.T)
        scope.update({f"q{i + 1}": q[:, i] for i in range(7)})
        scope.update({f"dq{i + 1}": dq[:, i] for i in range(7)})
        exec(code, scope)  # the authors' generated arithmetic, translated
        rows = scope[out]
        assert isinstance(rows, list)
        rows = [row if isinstance(row, list) else [row] for row in rows]
        n = q.shape[0]
        return np.array([[np.broadcast_to(v, (n,)) for v in row] for row in rows])

    def friction(self, qd: np.ndarray) -> np.ndarray:
        a, _k, c, b = self.fp  # get_FrictionTorque.m: A, k (unused), qdotsign, alpha
        return -a / (1 + np.exp(-b * c)) + a / (1 + np.exp(-b * (qd + c)))

    def torque(
        self, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, chunk: int = 256
    ) -> np.ndarray:
        parts = []
        for s in range(0, q.shape[0], chunk):
            qs, qds, qdds = q[s : s + chunk], qd[s : s + chunk], qdd[s : s + chunk]
            m = self._eval("MassMatrix", qs, qds)  # (7, 7, n)
            c = self._eval("CoriolisVector", qs, qds)[:, 0]  # (7, n)
            g = self._eval("GravityVector", qs, qds)[:, 0]
            parts.append(np.einsum("ijn,nj->ni", m, qdds) + c.T + g.T + self.friction(qds))
        return np.concatenate(parts)


def check_translation(model: MatlabModel) -> dict[str, float]:
    """The translated files against an independent transcription and against themselves."""
    from tests.model.gaz_reference import MASS_MATRICES, gravity_nm

    worst_m = worst_g = worst_c = 0.0
    zero = np.zeros((1, 7))
    for q_list, m_ref in MASS_MATRICES:
        q = np.asarray(q_list)[None]
        m = model._eval("MassMatrix", q, zero)[:, :, 0]
        g = model._eval("GravityVector", q, zero)[:, 0, 0]
        worst_m = max(worst_m, float(np.abs(m - np.asarray(m_ref)).max()))
        worst_g = max(worst_g, float(np.abs(g - gravity_nm(q[0])).max()))
    rng = np.random.default_rng(0)
    h = 1e-6
    for _ in range(3):
        q, qd = rng.uniform(-1.5, 1.5, 7), rng.uniform(-1.0, 1.0, 7)
        dm = np.zeros((7, 7, 7))  # dM_ij / dq_k
        for k in range(7):
            e = np.zeros(7)
            e[k] = h
            plus = model._eval("MassMatrix", (q + e)[None], zero)[:, :, 0]
            minus = model._eval("MassMatrix", (q - e)[None], zero)[:, :, 0]
            dm[:, :, k] = (plus - minus) / (2 * h)
        christoffel = np.einsum("ijk,j,k->i", dm, qd, qd) - 0.5 * np.einsum(
            "jki,j,k->i", dm, qd, qd
        )
        c = model._eval("CoriolisVector", q[None], qd[None])[:, 0, 0]
        worst_c = max(worst_c, float(np.abs(c - christoffel).max()))
    if worst_m > 1e-8 or worst_g > 1e-9 or worst_c > 1e-6:
        raise SystemExit(
            f"error: the translated MATLAB model disagrees (M {worst_m:.2g}, g {worst_g:.2g}, "
            f"c {worst_c:.2g}): not the files of commit 24d85ce?"
        )
    return {"mass_matrix_nm": worst_m, "gravity_nm": worst_g, "coriolis_christoffel_nm": worst_c}


def pinocchio_torque(q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """RNEA with the feasible parameters (arm as identified, no hand) + their friction."""
    from dataclasses import replace

    import pinocchio as pin

    from pipeline.model.published import GAZ_PANDA, describes, gaz_links
    from pipeline.robots.loaders import load_spec
    from pipeline.robots.urdf import build_pinocchio_model

    spec = load_spec("panda")
    why = describes(GAZ_PANDA, spec)
    if why:
        raise SystemExit(f"error: {why}")
    joints = tuple(
        replace(j, inertial=link, armature=0.0)
        for j, link in zip(spec.joints, gaz_links(hand=False), strict=True)
    )
    model = build_pinocchio_model(replace(spec, joints=joints))
    model.gravity.linear[:] = [0.0, 0.0, -9.80665]
    data = model.createData()
    tau = np.array([pin.rnea(model, data, a, b, c) for a, b, c in zip(q, qd, qdd, strict=True)])
    return tau + GAZ_PANDA.friction.torque_nm(qd)


def rms(x: np.ndarray) -> np.ndarray:
    return np.sqrt(np.nanmean(x**2, axis=0))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--log-dir", type=Path, required=True)
    ap.add_argument("--model-dir", type=Path, required=True)
    args = ap.parse_args()

    from pipeline.identify.fit import kept_rows
    from pipeline.identify.model_file import load_model
    from pipeline.identify.samples import joint_samples
    from pipeline.identify.stage import predict, read_options
    from pipeline.log.reader import read_recording

    out: dict[str, object] = {
        "machine": platform.machine(),
        "python": platform.python_version(),
        "load_before": os.getloadavg(),
    }
    log_files = [f"exciting_traj_{n}.txt" for n in ("time", "positions", "velocity", "torques")]
    model_files = [
        f"get_{n}.m" for n in ("MassMatrix", "CoriolisVector", "GravityVector", "FrictionTorque")
    ]
    for folder, names in ((args.log_dir, log_files), (args.model_dir, model_files)):
        missing = [n for n in names if not (folder / n).is_file()]
        if missing:
            raise SystemExit(f"error: {folder}: no {missing[0]} (expected {', '.join(names)})")
    t, q, qd, tau = read_log(args.log_dir)
    periods = np.diff(t)
    split_s = t[0] + FIT_SHARE * (t[-1] - t[0])
    fit_rows = t < split_s
    out.update(
        samples=int(t.size),
        duration_s=float(t[-1] - t[0]),
        period_range_ms=[float(periods.min() * 1e3), float(periods.max() * 1e3)],
        repeated_samples=int(np.all(q[1:] == q[:-1], axis=1).sum()),
        split_s=float(split_s),
        fit_samples=int(fit_rows.sum()),
        held_out_samples=int((~fit_rows).sum()),
    )
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        fit_bag, held_bag, model_path = tmp / "fit", tmp / "held_out", tmp / "model.yaml"
        write_bag(fit_bag, t[fit_rows], q[fit_rows], qd[fit_rows], tau[fit_rows])
        write_bag(held_bag, t[~fit_rows], q[~fit_rows], qd[~fit_rows], tau[~fit_rows])
        fit_cmd = ["identify", "fit", str(fit_bag), "--robot", "panda", "--friction", "sigmoid",
                   "--torque-side", "link", "--out", str(model_path), "--json"]  # fmt: skip
        val_cmd = ["identify", "validate", str(model_path), str(held_bag), "--json"]
        for label, cmd in (("fit", fit_cmd), ("validate", val_cmd)):
            t0 = time.perf_counter()
            proc = subprocess.run(
                [sys.executable, "-m", "pipeline", *cmd],
                capture_output=True, text=True, env=env, check=False,
            )  # fmt: skip
            out[f"{label}_wall_s"] = time.perf_counter() - t0
            if proc.returncode != 0:
                raise SystemExit(f"pipeline {' '.join(cmd[:2])} refused: {proc.stderr.strip()}")
            out[label] = json.loads(proc.stdout)
        validation = out["validate"]
        assert isinstance(validation, dict)

        # the same held-out samples, through the Python API
        model = load_model(model_path)
        samples = joint_samples(
            read_recording(held_bag, read_options(None)), model.spec,
            cutoff_hz=float(validation["cutoff_hz"]),
        )  # fmt: skip
        ours = predict(model, samples, min_speed_rad_s=float(validation["min_speed_rad_s"]))
        measured = ours.measured_nm
        slow = np.isnan(measured)
        matlab = MatlabModel(args.model_dir)
        out["translation_check_max_abs"] = check_translation(matlab)
        theirs_m = matlab.torque(samples.q, samples.qd, samples.qdd)
        theirs_p = pinocchio_torque(samples.q, samples.qd, samples.qdd)
        theirs_m[slow] = np.nan
        theirs_p[slow] = np.nan
        # their model given what ours fits besides the dynamics: a per-joint torque offset,
        # the mean of their residual on the fit part's samples (same filter and rows)
        fit_samples = joint_samples(
            read_recording(fit_bag, read_options(None)), model.spec,
            cutoff_hz=float(validation["cutoff_hz"]),
        )  # fmt: skip
        fit_resid = matlab.torque(fit_samples.q, fit_samples.qd, fit_samples.qdd)
        fit_resid -= fit_samples.tau_nm
        # the rows the fit leaves out (slow, or near a stuck joint): the same rule, one function
        left_out = ~kept_rows(fit_samples, float(validation["min_speed_rad_s"]))
        fit_resid[left_out.reshape(fit_resid.shape)] = np.nan
        their_offset = np.nanmean(fit_resid, axis=0)
    ours_err = rms(ours.predicted_nm - measured)
    matlab_err = rms(theirs_m - measured)
    pin_err = rms(theirs_p - measured)
    offset_err = rms(theirs_m - their_offset - measured)
    tau_rms = rms(measured)
    if not np.allclose(ours_err, validation["rms_error_nm"], rtol=1e-9, atol=1e-12):
        raise SystemExit("error: the API's held-out error is not validate's")
    out.update(
        held_out_model_samples=int(samples.q.shape[0]),
        rms_torque_nm=tau_rms.tolist(),
        ours_rms_error_nm=ours_err.tolist(),
        theirs_matlab_rms_error_nm=matlab_err.tolist(),
        theirs_feasible_pinocchio_rms_error_nm=pin_err.tolist(),
        theirs_matlab_with_offset_rms_error_nm=offset_err.tolist(),
        their_offset_from_fit_part_nm=(-their_offset).tolist(),
        ratio_ours_to_theirs=(ours_err / matlab_err).tolist(),
        ratio_ours_to_theirs_with_offset=(ours_err / offset_err).tolist(),
        matlab_vs_pinocchio_max_nm=float(np.nanmax(np.abs(theirs_m - theirs_p))),
        load_after=os.getloadavg(),
    )
    print(json.dumps(out, indent=2))
    print()
    print("| joint | RMS torque [N m] | ours: held-out RMS error [N m] | theirs (MATLAB files) "
          "| ratio ours / theirs | theirs (feasible, Pinocchio) | theirs + offset "
          "| ratio ours / (theirs + offset) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for j, name in enumerate(JOINTS):
        print(
            f"| {name} | {tau_rms[j]:.3f} | {ours_err[j]:.3f} | {matlab_err[j]:.3f} | "
            f"{ours_err[j] / matlab_err[j]:.2f} | {pin_err[j]:.3f} | {offset_err[j]:.3f} | "
            f"{ours_err[j] / offset_err[j]:.2f} |"
        )


if __name__ == "__main__":
    main()
