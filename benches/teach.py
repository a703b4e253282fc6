"""Teach page latency: from a target update to the new arm pose arriving at the page.

``pipeline teach ur5 --solver S`` runs as its own process (as for a user); a
scripted client (:class:`pipeline.teach.wire.PageClient`) sends what the browser
sends while the gizmo is dragged (``TransformControlsUpdateMessage``) and times
until the server's message with the last link's new pose arrives: IK, FK check,
Jacobian, GUI updates, serialization, websocket, both ways. One target at a
time, the next sent after the previous answer.

Targets: a "drag", FK of a smooth joint path sampled at small steps (what a
gizmo drag produces), and "jumps", FK of random joints within +-1 rad of the
start (a target typed or dragged far). All are reachable. Every answer is
checked: the joints the page received must reach the target by DH FK.

Also timed in-process: ``TeachServer.update_target`` alone (the server's update
path up to the flush, no websocket).

    python benches/teach.py            # prints one JSON object
    python benches/teach.py --quick
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np
from ik import machine

from pipeline import transforms as tf
from pipeline.model.dh import forward_kinematics
from pipeline.robots import RobotSpec, load_spec
from pipeline.teach.server import BAD_RGB, MARKER_NODE, TeachServer, link_node
from pipeline.teach.session import TeachSession, choose_solver, home_pose
from pipeline.teach.wire import PageClient

TARGETS_MS = {"analytic": 20.0, "numeric": 50.0}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def drag_path(spec: RobotSpec, n: int) -> np.ndarray:
    """Joint vectors along a smooth closed path around the home pose (small steps)."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    amp = np.array([0.6, 0.4, 0.5, 0.5, 0.5, 0.8])[: spec.dof]
    phase = np.arange(spec.dof) * 0.7
    return np.clip(home_pose(spec) + amp * np.sin(t[:, None] + phase), spec.lower, spec.upper)


def jumps(spec: RobotSpec, n: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    return np.clip(home_pose(spec) + rng.uniform(-1.0, 1.0, (n, spec.dof)), spec.lower, spec.upper)


def stats(ms: list[float]) -> dict[str, float]:
    a = np.array(ms)
    return {
        "n": int(a.size),
        "p50": float(np.percentile(a, 50)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
        "mean": float(a.mean()),
    }


def page_fk_error(spec: RobotSpec, client: PageClient, target: np.ndarray) -> float:
    """Largest entry of |FK(joints the page shows) - target|."""
    q = [client.value(j) for j in spec.joint_names]
    return float(np.abs(forward_kinematics(spec, q) - target).max())


def through_page(spec: RobotSpec, solver: str, qs: np.ndarray) -> dict[str, Any]:
    """Latency target -> arm pose at the client, server in its own process."""
    port = _free_port()
    errors = tempfile.TemporaryFile(mode="w+")  # noqa: SIM115 (closed below; a full pipe would stall the server)
    proc = subprocess.Popen(
        [sys.executable, "-m", "pipeline", "teach", spec.name, "--solver", solver,
         "--port", str(port)],
        stdout=subprocess.PIPE, stderr=errors, text=True,
    )  # fmt: skip
    try:
        assert proc.stdout is not None
        while not (line := proc.stdout.readline()).startswith("teach:"):
            if not line and proc.poll() is not None:
                raise RuntimeError(f"pipeline teach exited with {proc.returncode}")
        last = link_node(spec.dof)

        def answer(m: dict[str, Any]) -> bool:
            """The new arm pose, or the marker turning red (unreachable)."""
            if m.get("name") == MARKER_NODE:
                return bool(m.get("updates", {}).get("color") == list(BAD_RGB))
            return m.get("type") == "SetPositionMessage" and m.get("name") == last

        latencies: list[float] = []
        unsolved = 0
        worst_fk = 0.0
        with PageClient(f"http://127.0.0.1:{port}/") as client:
            client.pump_until(lambda c: spec.joint_names[-1] in c.gui_label.values())
            for q in qs:
                target = forward_kinematics(spec, q)
                n = len(client.received)
                t0 = time.perf_counter()
                client.move_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))
                got = client.pump_until(lambda c, n=n: any(answer(m) for _, m in c.received[n:]))
                if not got:
                    raise RuntimeError(f"no answer to target {len(latencies)}")
                stamp, first = next((s, m) for s, m in client.received[n:] if answer(m))
                if first.get("name") == MARKER_NODE:  # marker turned red: IK gave up
                    unsolved += 1
                    continue
                latencies.append((stamp - t0) * 1e3)
                # the joints the page shows reach the target (slider updates share the frame)
                client.pump_until(
                    lambda c, target=target: page_fk_error(spec, c, target) < 1e-5, timeout_s=2.0
                )
                worst_fk = max(worst_fk, page_fk_error(spec, client, target))
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        errors.seek(0)
        err_text = errors.read()
        errors.close()
        if "Traceback" in err_text:
            raise RuntimeError(f"pipeline teach printed an error:\n{err_text}")
    return {**stats(latencies), "unsolved": unsolved,
            "worst_fk_error_of_page_joints": worst_fk}  # fmt: skip


def in_process(spec: RobotSpec, solver: str, qs: np.ndarray) -> dict[str, Any]:
    """``TeachServer.update_target`` alone: IK + checks + render + flush, no client.
    Timed whether or not IK succeeds (the page answers either way)."""
    ik, _ = choose_solver(spec, solver)
    server = TeachServer(TeachSession(spec, ik), robot_arg=spec.name, port=0)
    try:
        times, solve = [], []
        for q in qs:
            target = forward_kinematics(spec, q)
            t0 = time.perf_counter()
            state = server.update_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))
            times.append((time.perf_counter() - t0) * 1e3)
            solve.append(state.solve_time_ms)
    finally:
        server.close()
    return {**stats(times), "ik_solve_ms": stats(solve)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer targets (development)")
    args = parser.parse_args()
    n_drag, n_jump = (60, 30) if args.quick else (500, 200)
    spec = load_spec("ur5")
    info = machine()
    results: dict[str, Any] = {}
    for solver in ("analytic", "numeric"):
        drag, jump = drag_path(spec, n_drag), jumps(spec, n_jump)
        page_drag = through_page(spec, solver, drag)
        results[solver] = {
            "target_p95_ms": TARGETS_MS[solver],
            "page_drag": page_drag,
            "page_jumps": through_page(spec, solver, jump),
            "update_path_in_process_drag": in_process(spec, solver, drag),
            "met": page_drag["p95"] <= TARGETS_MS[solver],
        }
    out = {
        "benchmark": "teach",
        "robot": spec.name,
        "command": "python benches/teach.py" + (" --quick" if args.quick else ""),
        "machine": {**info, "loadavg_1min_at_end": os.getloadavg()[0]},
        "targets": {"drag": n_drag, "jumps": n_jump},
        "results": results,
    }
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
