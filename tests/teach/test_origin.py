"""Only the page itself drives the teach server: a websocket from another Origin is refused,
and what a client sends that cannot be acted on is told to that client, not printed."""

from __future__ import annotations

import math
import socket

import pytest
from websockets.exceptions import InvalidStatus

from pipeline.teach.origin import own_origin
from pipeline.teach.server import TeachServer
from pipeline.teach.wire import PageClient


@pytest.mark.parametrize(
    "origin",
    [
        "http://evil.example",
        "http://evil.example:{port}",  # DNS rebinding: a name that resolves to 127.0.0.1
        "http://127.0.0.1:{other}",  # another local server's page
        "https://attacker.test:{port}",
        "null",  # a sandboxed iframe or a file:// page
        "file://",
    ],
)
def test_a_websocket_from_another_origin_is_refused(ur5_server: TeachServer, origin: str) -> None:
    origin = origin.format(port=ur5_server.port, other=ur5_server.port + 1)
    with pytest.raises(InvalidStatus) as info:
        PageClient(ur5_server.url, origin=origin, timeout_s=5)
    assert info.value.response.status_code == 403


@pytest.mark.parametrize("name", ["127.0.0.1", "localhost"])
def test_the_page_s_own_origin_is_accepted(ur5_server: TeachServer, name: str) -> None:
    with PageClient(ur5_server.url, origin=f"http://{name}:{ur5_server.port}") as client:
        assert client.pump_until(lambda c: bool(c.gui_label))


def _own_non_loopback_ip() -> str:
    """An address of this machine other than 127.0.0.1 (the route out; 127.0.0.2 if none)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.connect(("192.0.2.1", 9))  # no packet is sent: picks the outgoing interface
            return str(probe.getsockname()[0])
        except OSError:
            return "127.0.0.2"  # all of 127/8 is this machine's


def test_own_origin_rules() -> None:
    assert own_origin("http://127.0.0.1:8080", host="127.0.0.1", port=8080)
    assert own_origin("http://[::1]:8080", host="127.0.0.1", port=8080)
    assert not own_origin("http://127.0.0.1:8081", host="127.0.0.1", port=8080)
    assert not own_origin("http://192.168.1.7:8080", host="127.0.0.1", port=8080)
    # listening on all interfaces: only this machine's own addresses, not any IP literal
    assert own_origin("http://127.0.0.1:8080", host="0.0.0.0", port=8080)
    assert own_origin(f"http://{_own_non_loopback_ip()}:8080", host="0.0.0.0", port=8080)
    for foreign in ("203.0.113.5", "192.0.2.1", "0.0.0.0", "224.0.0.1", "[2001:db8::1]"):
        assert not own_origin(f"http://{foreign}:8080", host="0.0.0.0", port=8080), foreign
    assert not own_origin("http://rebind.example:8080", host="0.0.0.0", port=8080)
    assert own_origin("http://armlab.local:8080", host="armlab.local", port=8080)
    assert not own_origin("http://127.0.0.1:99999999", host="127.0.0.1", port=8080)


def _notified(client: PageClient, text: str) -> bool:
    return any(
        m.get("type", "").startswith("Notification") and text in str(m) for _, m in client.received
    )


@pytest.mark.parametrize(
    ("position", "wxyz", "said"),
    [
        ([math.nan, 0.0, 0.5], [1.0, 0.0, 0.0, 0.0], "finite position"),
        ([0.3, 0.1, 0.5], [0.0, 0.0, 0.0, 0.0], "zero quaternion"),
    ],
)
def test_a_bad_target_is_told_to_that_client_not_printed(
    ur5_server: TeachServer,
    capfd: pytest.CaptureFixture[str],
    position: list[float],
    wxyz: list[float],
    said: str,
) -> None:
    with PageClient(ur5_server.url) as client:
        assert client.pump_until(lambda c: bool(c.gui_label))
        client.move_target(position, wxyz)
        assert client.pump_until(lambda c: _notified(c, said)), "no notification came back"
    assert "Traceback" not in capfd.readouterr().err


def test_a_bad_solution_choice_and_map_size_are_told_to_that_client(
    ur5_server: TeachServer, capfd: pytest.CaptureFixture[str]
) -> None:
    with PageClient(ur5_server.url) as client:
        assert client.pump_until(lambda c: bool(c.gui_label))
        client.set_gui("IK solution", "zzz")
        assert client.pump_until(lambda c: _notified(c, "IK solution"))
        client.set_gui("samples", 10**9)
        client.set_gui("Show error map", True)
        assert client.pump_until(lambda c: _notified(c, "samples"))
    assert "Traceback" not in capfd.readouterr().err
