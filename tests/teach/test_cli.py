"""`pipeline teach` as a user runs it: starts on localhost, stops cleanly on Ctrl-C,
and refuses a busy port in one line."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pipeline.teach.wire import PageClient

pytestmark = pytest.mark.slow

PIPELINE = [sys.executable, "-m", "pipeline"]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _start(*args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "COLUMNS": "200"}
    return subprocess.Popen([*PIPELINE, "teach", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)  # fmt: skip


def _wait_for_url(proc: subprocess.Popen[str], timeout_s: float = 60.0) -> str:
    assert proc.stdout is not None
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith("teach:"):
            return line.split(" at ")[1].split()[0]
        if not line and proc.poll() is not None:
            raise AssertionError(f"teach exited early: {proc.stderr.read() if proc.stderr else ''}")
    raise AssertionError("teach never printed its URL")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_teach_serves_on_localhost_and_stops_cleanly(sig: signal.Signals) -> None:
    port = _free_port()
    proc = _start("ur5", "--port", str(port))
    try:
        url = _wait_for_url(proc)
        assert url == f"http://127.0.0.1:{port}/"
        with PageClient(url) as client:  # the page is really there
            assert client.pump_until(lambda c: "shoulder_pan_joint" in c.gui_label.values())
        proc.send_signal(sig)  # what Ctrl-C sends
        out, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "teach: stopped" in out
    with socket.socket() as s:  # the port is free again: no orphan server listens on it
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # closed connections linger
        s.bind(("127.0.0.1", port))


def test_busy_port_is_one_line_suggesting_port() -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        proc = _start("ur5", "--port", str(port))
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: port ") and "--port" in lines[0]


def test_robot_without_closed_form_says_why_numeric(tmp_path: Path) -> None:
    port = _free_port()
    proc = _start("mdh_example", "--port", str(port))
    try:
        _wait_for_url(proc)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0
    assert "note: no closed form for this robot" in err and "using numeric" in err


def test_unknown_robot_is_one_line() -> None:
    proc = _start("ur55", "--port", str(_free_port()))
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1
    assert err.count("\n") == 1 and err.startswith("error: ") and "ur55" in err
