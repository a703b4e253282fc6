"""Identification of a real robot's log: a 20 s, 7-joint ``/joint_states``-only bag -> MODEL.yaml.

Prints one JSON object. Outside the clock: a 20 s excitation (2 periods of a 0.1 Hz,
5-harmonic Fourier series, not optimized) of the Panda on the ``panda-box`` scenario's
realistic plant (drawn links, Coulomb friction, damping, sensor noise; seed 0) at 1 kHz,
rewritten by rosbags as a robot driver logs it: only ``/joint_states`` (position,
velocity, measured effort), no controller state, no metadata, samples kept with gaps of
1-3 ms (uneven stamps) and 6 % of the messages repeated (same stamp, or a stale state
1 ms later). Timed: ``pipeline identify fit LOG --robot panda`` as a command (a fresh
process: imports, read, filter, regressor, WLS, physical projection, write), with the
default Coulomb model and with ``--friction sigmoid``. Target: <= 15 s.

Usage: python benches/identify_real_log.py
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from pipeline.control import make_controller  # noqa: E402
from pipeline.identify.excitation import scenario_plant  # noqa: E402
from pipeline.identify.fourier import FourierReference  # noqa: E402
from pipeline.params import load_params  # noqa: E402
from pipeline.robots.loaders import load_spec  # noqa: E402
from pipeline.sim.runner import run_episode  # noqa: E402

READY = np.array([0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398])
T0_NS = 1_700_000_000_000_000_000


def simulate() -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Names, stamps [ns from 0], measured q, qd and applied effort at 1 kHz."""
    params = load_params(REPO / "params.yaml")
    scenario = params.scenarios["panda-box"]
    spec = load_spec(scenario.robot)
    plant_spec, plant, _ = scenario_plant(spec, scenario, seed=0)
    free = np.random.default_rng(1).normal(scale=0.03, size=2 * 7 * 4)
    ref = FourierReference.from_free(READY, free, harmonics=5, base_frequency_hz=0.1, periods=2)
    result = run_episode(
        spec, reference=ref, controller=make_controller("ctc", spec), plant=plant,
        plant_spec=plant_spec, seed=0, hold_s=0.0, preroll_s=0.0,
        position_noise_std_rad=scenario.plant.position_noise_std_rad,
        velocity_noise_std_rad_s=scenario.plant.velocity_noise_std_rad_s,
    )  # fmt: skip
    assert result.status == "ok", result.reason
    return (
        list(spec.joint_names),
        np.asarray(result.stamp_ns),
        np.asarray(result.q),
        np.asarray(result.qd),
        np.asarray(result.tau_nm),
    )


def write_log(path: Path) -> dict[str, float]:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    names, stamps, q, qd, tau = simulate()
    rng = np.random.default_rng(0)
    idx = np.cumsum(rng.integers(1, 4, size=stamps.size))
    idx = idx[idx < stamps.size]
    store = get_typestore(Stores.ROS2_JAZZY)
    t = store.types
    header_t, time_t, js_t = (
        t["std_msgs/msg/Header"], t["builtin_interfaces/msg/Time"], t["sensor_msgs/msg/JointState"]
    )  # fmt: skip
    repeats = 0
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/joint_states", js_t.__msgtype__, typestore=store)
        for i, k in enumerate(idx):
            # a repeat: the same message again, or (where the next sample is >= 2 ms away)
            # the same state republished 1 ms later
            room = i + 1 < idx.size and idx[i + 1] - k >= 2
            copies = [0] + ([int(rng.integers(0, 2)) * int(room)] if rng.random() < 0.06 else [])
            repeats += len(copies) - 1
            for off in copies:
                ns = T0_NS + int(stamps[k]) + off * 1_000_000
                header = header_t(stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="")
                msg = js_t(header=header, name=names, position=q[k], velocity=qd[k], effort=tau[k])
                w.write(conn, ns, store.serialize_cdr(msg, js_t.__msgtype__))
    return {
        "log_duration_s": float(stamps[idx[-1]] - stamps[idx[0]]) * 1e-9,
        "messages": int(idx.size + repeats),
        "repeated_written": repeats,
    }


def main() -> None:
    out: dict[str, object] = {
        "machine": platform.machine(),
        "python": platform.python_version(),
        "load_before": os.getloadavg(),
    }
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "robot_log"
        out.update(write_log(log))
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        runs = (
            ("coulomb", []),
            ("sigmoid", ["--friction", "sigmoid"]),
            ("sigmoid_fitted", ["--friction", "sigmoid", "--transition-speed", "auto"]),
        )
        for label, extra in runs:
            model = str(Path(tmp) / f"{label}.yaml")
            cmd = [sys.executable, "-m", "pipeline", "identify", "fit", str(log), "--robot",
                   "panda", "--out", model, "--json", *extra]  # fmt: skip
            t0 = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
            wall = time.perf_counter() - t0
            if proc.returncode != 0:
                raise SystemExit(proc.stderr)
            s = json.loads(proc.stdout)
            out[f"fit_{label}_wall_s"] = wall
            out[f"fit_{label}_inner_s"] = s["wall_s"]
            out[f"fit_{label}_equations"] = s["equations"]
            out[f"fit_{label}_repeats_dropped"] = (
                s["repeated_stamps_dropped"] + s["repeated_values_dropped"]
            )
            out[f"fit_{label}_residual_rms_nm"] = [round(x, 4) for x in s["residual_rms_nm"]]
            out[f"fit_{label}_transition_speed_rad_s"] = s["transition_speed_rad_s"]
        out["fit_target_s"] = 15.0
    out["load_after"] = os.getloadavg()
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
