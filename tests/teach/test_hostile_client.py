"""A hostile or broken client: teach writes only its own params file, whatever a client
sends; malformed websocket messages are one logged line each, never a traceback, and the
session stays usable."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import msgspec
import numpy as np
import pytest

from pipeline import transforms as tf
from pipeline.model.dh import forward_kinematics
from pipeline.teach.wire import PageClient
from tests.teach.conftest import start_server

REPO = Path(__file__).resolve().parents[2]


def _deep(depth: int) -> bytes:
    # msgpack: `depth` nested one-element arrays around 0 (a 100k-deep value)
    return b"\x91" * depth + b"\x00"


MALFORMED = [
    ("random bytes", os.urandom(64) + b"\xc1"),
    ("unknown type", msgspec.msgpack.encode({"type": "NoSuchMessage", "x": 1})),
    ("no type", msgspec.msgpack.encode({"uuid": "x"})),
    ("missing fields", msgspec.msgpack.encode({"type": "GuiUpdateMessage"})),
    ("not a mapping", msgspec.msgpack.encode([1, 2, 3])),
    ("deep nesting", _deep(100_000)),
]


def test_malformed_messages_are_one_logged_line_and_the_session_stays_usable(
    capfd: pytest.CaptureFixture[str],
) -> None:
    server = start_server("ur5")
    try:
        with PageClient(server.url) as client:
            assert client.pump_until(lambda c: bool(c.gui_label))
            for _, raw in MALFORMED:
                client._ws.send(raw)
            joint = server.session.spec.joint_names[1]
            client.set_gui(joint, "abc")
            client.set_gui(joint, [1, 2])
            client.pump(0.5)
            # still usable: a drag moves the arm
            target = forward_kinematics(server.session.spec, [0.3, -1.0, 1.2, -0.5, 0.8, -0.2])
            client.move_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))
            assert client.pump_until(
                lambda c: bool(np.allclose(server.state.target, target, atol=1e-9))
            ), "the session stopped answering after malformed messages"
    finally:
        server.close()
    err = capfd.readouterr().err
    assert "Traceback" not in err, err[-3000:]
    lines = [ln for ln in err.splitlines() if "armlab teach: ignored a malformed message" in ln]
    assert len(lines) >= len(MALFORMED), err[-3000:]


def test_teach_writes_only_its_own_params_file_whatever_the_client_sends(
    tmp_path: Path,
) -> None:
    own = tmp_path / "own.yaml"
    other = tmp_path / "other.yaml"
    shutil.copy(REPO / "params.yaml", own)
    shutil.copy(REPO / "params.yaml", other)
    before = other.read_bytes()
    server = start_server("ur5", params=str(own))
    try:
        with PageClient(server.url) as client:
            assert client.pump_until(lambda c: bool(c.gui_label))
            client.set_gui("params file", str(other))
            client.set_gui("scenario", "from-page")
            client.set_gui("goal as", "joints")
            client.set_gui("Write goal", True)
            assert client.pump_until(
                lambda c: any("teach writes only the file" in str(m) for _, m in c.received)
            ), "no refusal came back"
    finally:
        server.close()
    assert other.read_bytes() == before
    assert "from-page" not in own.read_text()
