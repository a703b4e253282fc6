"""Bags we did not write (rosbags, Humble, sqlite3) and bad input, each one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from pipeline.errors import IdentificationError
from pipeline.identify.fit import identify
from pipeline.identify.samples import joint_samples
from pipeline.identify.stage import fit_command, validate_command
from pipeline.log.reader import read_recording
from pipeline.robots.loaders import load_spec
from tests.log.rosbags_msgs import EMPTY, RosMsgs

from .conftest import fourier, record

T0_NS = 1_700_000_000_000_000_000  # wall-clock stamps, as a real robot's bag has


def write_humble_db3(
    path: Path,
    *,
    names: list[str],
    q: np.ndarray,
    qd: np.ndarray,
    effort: np.ndarray | None,
    period_ns: int = 1_000_000,
) -> None:
    """A Humble robot's sqlite3 bag by rosbags: /joint_states (joints in ``names`` order)
    and the JTC's controller state, no armlab metadata, no robot description."""
    m = RosMsgs("humble")
    js_t = m.type("sensor_msgs/msg/JointState")
    cs_t = m.type("control_msgs/msg/JointTrajectoryControllerState")
    with Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as w:
        c_cs = w.add_connection("/arm_controller/state", cs_t.__msgtype__, typestore=m.store)
        c_js = w.add_connection("/joint_states", js_t.__msgtype__, typestore=m.store)
        for k in range(q.shape[0]):
            ns = T0_NS + k * period_ns
            p = m.point(q[k])
            cs = m.controller_state(
                ns=ns, joints=names, reference=p, feedback=p, error=m.point(q[k] * 0),
                output=m.point(),
            )  # fmt: skip
            w.write(c_cs, ns, m.cdr(cs))
            js = m.joint_state(
                ns=ns,
                names=names,
                position=q[k],
                velocity=qd[k],
                effort=effort[k] if effort is not None else EMPTY,
            )
            w.write(c_js, ns, m.cdr(js))


def _truth(bag: Path) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Our recording's true q, qd and applied effort, joints shuffled (a robot's order)."""
    spec = load_spec("ur5")
    s = joint_samples(read_recording(bag), spec, cutoff_hz=0.0)
    order = [3, 0, 5, 1, 4, 2]
    names = [spec.joint_names[i] for i in order]

    # joint_samples dropped the last sample (forward difference); fine for a foreign bag
    def pick(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a[:, order])

    return names, pick(s.q), pick(s.qd), pick(s.tau_nm)


def test_a_humble_db3_bag_by_rosbags_identifies_like_ours(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    names, q, qd, tau = _truth(ideal_bags[0])
    foreign = tmp_path / "robot_run"
    write_humble_db3(foreign, names=names, q=q, qd=qd, effort=tau)
    ours = fit_command([ideal_bags[0]], out=tmp_path / "ours.yaml", cutoff_hz=0.0)
    theirs = fit_command([foreign], out=tmp_path / "theirs.yaml", robot="ur5", cutoff_hz=0.0)
    assert theirs["base_parameters"] == ours["base_parameters"]
    spec = load_spec("ur5")
    a = identify(spec, [joint_samples(read_recording(foreign), spec, cutoff_hz=0.0)])
    b = identify(spec, [joint_samples(read_recording(ideal_bags[0]), spec, cutoff_hz=0.0)])
    np.testing.assert_allclose(a.beta_wls, b.beta_wls, rtol=1e-6, atol=1e-9)
    # and the model it makes predicts our other recording
    check = validate_command(tmp_path / "theirs.yaml", [ideal_bags[1]], cutoff_hz=0.0)
    assert max(check["rms_error_pct"]) < 1e-4


def test_a_bag_without_efforts_is_refused(ideal_bags: tuple[Path, Path], tmp_path: Path) -> None:
    names, q, qd, _ = _truth(ideal_bags[0])
    path = tmp_path / "no_effort"
    write_humble_db3(path, names=names, q=q[:2000], qd=qd[:2000], effort=None)
    with pytest.raises(IdentificationError, match="has no efforts"):
        fit_command([path], out=tmp_path / "m.yaml", robot="ur5")
    assert not (tmp_path / "m.yaml").exists()


def test_a_bag_of_another_robot_is_refused(ideal_bags: tuple[Path, Path], tmp_path: Path) -> None:
    _, q, qd, tau = _truth(ideal_bags[0])
    path = tmp_path / "other"
    write_humble_db3(
        path, names=[f"j{i}" for i in range(6)], q=q[:500], qd=qd[:500], effort=tau[:500]
    )
    model = tmp_path / "m.yaml"
    fit_command([ideal_bags[0]], out=model, cutoff_hz=0.0)
    with pytest.raises(IdentificationError, match="no joint shoulder_pan_joint of robot 'ur5'"):
        validate_command(model, [path])


def test_an_unexcited_regressor_names_the_parameters(tmp_path: Path) -> None:
    """Only the shoulder joints move: the wrists' parameters are not excited."""
    bag = record(tmp_path / "two_joints", fourier(3, joints=slice(0, 2)), hold_s=0.1)
    with pytest.raises(IdentificationError, match=r"too ill-conditioned.*not excited: .*wrist"):
        fit_command([bag], out=tmp_path / "m.yaml")
    assert not (tmp_path / "m.yaml").exists()


def test_cli_says_a_too_short_bag_in_one_line(
    ideal_bags: tuple[Path, Path], tmp_path: Path
) -> None:
    names, q, qd, tau = _truth(ideal_bags[0])
    path = tmp_path / "short"
    write_humble_db3(path, names=names, q=q[:60], qd=qd[:60], effort=tau[:60])
    out = tmp_path / "m.yaml"
    proc = subprocess.run(
        [sys.executable, "-m", "pipeline", "identify", "fit", str(path), "--out", str(out),
         "--robot", "ur5", "--cutoff-hz", "0"],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "too short" in lines[0]
    assert not out.exists()
