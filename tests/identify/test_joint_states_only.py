"""A real robot's log: only ``/joint_states`` (position, velocity, effort), written by
rosbags (an independent writer), uneven stamps and repeated samples, no controller state,
no metadata. Made from a simulated excitation of the UR5 (the ideal plant of conftest)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from pipeline.errors import IdentificationError, RecordingError
from pipeline.identify.samples import joint_samples
from pipeline.identify.stage import fit_command, validate_command
from pipeline.log.reader import read_recording
from pipeline.robots.loaders import load_spec

from .test_inputs import T0_NS, _truth

TOPIC = "/franka/joint_states"


def write_joint_states(
    path: Path,
    *,
    names: list[str],
    stamps_ns: np.ndarray,
    q: np.ndarray,
    qd: np.ndarray,
    effort: np.ndarray | None,
) -> None:
    """An MCAP bag by rosbags with one topic, ``TOPIC`` (sensor_msgs/JointState)."""
    store = get_typestore(Stores.ROS2_JAZZY)
    t = store.types
    header_t, time_t, js_t = (
        t["std_msgs/msg/Header"],
        t["builtin_interfaces/msg/Time"],
        t["sensor_msgs/msg/JointState"],
    )
    empty = np.zeros(0)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection(TOPIC, js_t.__msgtype__, typestore=store)
        for k, ns in enumerate(int(x) for x in stamps_ns):
            header = header_t(stamp=time_t(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="")
            msg = js_t(
                header=header,
                name=names,
                position=q[k],
                velocity=qd[k],
                effort=effort[k] if effort is not None else empty,
            )
            w.write(conn, ns, store.serialize_cdr(msg, js_t.__msgtype__))


def real_log(bag: Path, *, seed: int) -> dict[str, object]:
    """The simulation's 1 kHz samples as a robot driver logs them: samples kept with gaps of
    1-3 ms (uneven stamps), some messages sent twice (same stamp), some stale states
    republished 1 ms later (same values, new stamp)."""
    names, q, qd, tau = _truth(bag)
    rng = np.random.default_rng(seed)
    idx = np.cumsum(rng.integers(1, 4, size=q.shape[0]))
    idx = idx[idx < q.shape[0]]
    stamps = T0_NS + idx * 1_000_000
    rows = list(range(idx.size))
    gaps = np.diff(idx)
    stale = [k for k in np.flatnonzero(gaps >= 2) if rng.random() < 0.04]
    twice = [k for k in range(idx.size) if rng.random() < 0.03 and k not in stale]
    order: list[tuple[int, int]] = []  # (row, stamp offset [ms])
    for k in rows:
        order.append((k, 0))
        if k in twice:
            order.append((k, 0))
        if k in stale:
            order.append((k, 1))
    pick = np.array([idx[k] for k, _ in order])
    return {
        "names": names,
        "stamps_ns": np.array([stamps[k] + off * 1_000_000 for k, off in order]),
        "q": q[pick],
        "qd": qd[pick],
        "effort": tau[pick],
        "twice": len(twice),
        "stale": len(stale),
    }


def test_a_joint_states_only_bag_fits_and_validates(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    logs = []
    for k, bag in enumerate(ideal_bags):
        log = real_log(bag, seed=k)
        path = tmp_path / f"robot_{k}"
        write_joint_states(
            path,
            names=log["names"],  # type: ignore[arg-type]
            stamps_ns=log["stamps_ns"],  # type: ignore[arg-type]
            q=log["q"],  # type: ignore[arg-type]
            qd=log["qd"],  # type: ignore[arg-type]
            effort=log["effort"],  # type: ignore[arg-type]
        )
        logs.append((path, log))
    (fit_bag, fit_log), (check_bag, check_log) = logs
    # the report still needs its controller state; identification does not
    with pytest.raises(RecordingError, match="controller_state") as refused:
        read_recording(fit_bag)
    assert "no reference to measure tracking against: `pipeline identify fit`" in str(refused.value)
    model = tmp_path / "model.yaml"
    s = fit_command(
        [fit_bag], out=model, robot="ur5", cutoff_hz=5.0, topics={"joint_states": TOPIC}
    )
    assert s["repeated_stamps_dropped"] == fit_log["twice"] > 0
    assert s["repeated_values_dropped"] == fit_log["stale"] > 0
    assert s["resampled"] == [str(fit_bag)]
    check = validate_command(model, [check_bag], topics={"joint_states": TOPIC})
    assert max(check["rms_error_pct"]) < 3.0, check["rms_error_pct"]
    # validate drops and resamples as fit does, and says so
    assert check["repeated_stamps_dropped"] == check_log["twice"] > 0
    assert check["repeated_values_dropped"] == check_log["stale"] > 0
    assert check["resampled"] == [str(check_bag)]
    proc = _cli("validate", str(model), str(check_bag), "--topic", f"joint_states={TOPIC}")
    assert proc.returncode == 0, proc.stderr
    assert (
        f"samples: {check_log['twice']} repeated stamps and {check_log['stale']} repeated "
        "values dropped; 1 of 1 recording(s) resampled"
    ) in proc.stdout, proc.stdout


def test_repeated_samples_are_dropped_and_uneven_stamps_resampled(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    log = real_log(ideal_bags[0], seed=5)
    path = tmp_path / "robot"
    write_joint_states(path, **{k: log[k] for k in ("names", "stamps_ns", "q", "qd", "effort")})  # type: ignore[arg-type]
    from pipeline.identify.stage import read_options

    spec = load_spec("ur5")
    s = joint_samples(read_recording(path, read_options(None)), spec, cutoff_hz=5.0)
    assert (s.repeated_stamps, s.repeated_values, s.resampled) == (log["twice"], log["stale"], True)
    assert s.period_range_s == pytest.approx((0.001, 0.003))


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "pipeline", "identify", *args],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip


def _one_line_error(proc: subprocess.CompletedProcess[str], *words: str) -> None:
    assert proc.returncode != 0, proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    for w in words:
        assert w in lines[0], lines[0]


@pytest.mark.slow
def test_bad_real_logs_are_one_line_and_write_nothing(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    log = real_log(ideal_bags[0], seed=7)
    cols = {k: log[k] for k in ("names", "stamps_ns", "q", "qd")}
    no_effort = tmp_path / "no_effort"
    write_joint_states(no_effort, effort=None, **cols)  # type: ignore[arg-type]
    short = tmp_path / "short"
    write_joint_states(
        short,
        names=log["names"],  # type: ignore[arg-type]
        stamps_ns=log["stamps_ns"][:100],  # type: ignore[index]
        q=log["q"][:100],  # type: ignore[index]
        qd=log["qd"][:100],  # type: ignore[index]
        effort=log["effort"][:100],  # type: ignore[index]
    )
    out = tmp_path / "m.yaml"
    _one_line_error(_cli("fit", str(no_effort), "--out", str(out), "--robot", "ur5"), "no efforts")
    _one_line_error(
        _cli("fit", str(short), "--out", str(out), "--robot", "panda"),
        "no joint panda_joint1 of robot 'panda'",
    )
    _one_line_error(
        _cli("fit", str(short), "--out", str(out), "--robot", "ur5", "--cutoff-hz", "0"),
        "too short",
        "not excited: ",
    )
    assert not out.exists()
    with pytest.raises(IdentificationError, match="--torque-side"):
        fit_command([short], out=out, robot="ur5", torque_side="gearbox")
