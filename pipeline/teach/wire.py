"""A scripted client of the teach page: speaks viser's websocket protocol, as the browser does.

It sends what the browser sends when the user drags the gizmo
(``TransformControlsUpdateMessage``) and keeps what the server sends back: node
poses (``Set{Position,Orientation}Message``) and GUI values (sliders by label).
Tests and ``benches/teach.py`` use it to drive a running page end to end.

Server -> client frames (viser 1.x ``infra._infra._message_producer``): 8 bytes
msgpack size, 8 bytes compressed size (little endian), zstd-compressed msgpack
``{"messages": [...]}``, then raw binary buffers (mesh data; skipped here).
Client -> server frames are one plain msgpack message with a ``type`` field.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import msgspec
import viser
import zstandard
from websockets.sync.client import ClientConnection, connect
from websockets.typing import Origin, Subprotocol

from pipeline.teach.server import TARGET_NODE


class PageClient:
    """One websocket connection to a teach page.

    Args:
        url: the page URL (``http://127.0.0.1:8080/``) or its ``ws://`` form.
        timeout_s: how long :meth:`pump_until` waits by default [s].
        origin: the ``Origin`` header to send (a browser sends its page's; None: none).
    """

    def __init__(self, url: str, *, timeout_s: float = 10.0, origin: str | None = None) -> None:
        ws_url = "ws" + url.removeprefix("http") if url.startswith("http") else url
        self._ws: ClientConnection = connect(
            ws_url,
            origin=Origin(origin) if origin is not None else None,
            subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],
            max_size=None,
            open_timeout=timeout_s,
        )
        self._timeout_s = timeout_s
        self._dctx = zstandard.ZstdDecompressor()
        self.positions: dict[str, tuple[float, ...]] = {}
        self.orientations: dict[str, tuple[float, ...]] = {}
        self.gui_label: dict[str, str] = {}
        self.gui_value: dict[str, Any] = {}
        self.gui_props: dict[str, dict[str, Any]] = {}
        self.received: list[tuple[float, dict[str, Any]]] = []
        # the browser reports its camera first; viser registers a client (and routes
        # its GUI events) only after that
        self.send(
            {
                "type": "ViewerCameraMessage",
                "wxyz": [1.0, 0.0, 0.0, 0.0],
                "position": [1.3, -1.3, 0.9],
                "fov": 1.0,
                "near": 0.01,
                "far": 100.0,
                "image_height": 800,
                "image_width": 1280,
                "look_at": [0.0, 0.0, 0.15],
                "up_direction": [0.0, 0.0, 1.0],
            }
        )

    def close(self) -> None:
        self._ws.close()

    def __enter__(self) -> PageClient:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()

    def send(self, message: dict[str, Any]) -> None:
        """Send one client -> server message (a dict with ``type``)."""
        self._ws.send(msgspec.msgpack.encode(message))

    def move_target(self, position_m: Sequence[float], wxyz: Sequence[float]) -> None:
        """What the browser sends while the user drags the flange-target gizmo."""
        self.send(
            {
                "type": "TransformControlsUpdateMessage",
                "name": TARGET_NODE,
                "wxyz": [float(v) for v in wxyz],
                "position": [float(v) for v in position_m],
                "owner": "",
            }
        )

    def set_gui(self, label: str, value: Any) -> None:
        """What the browser sends when the user changes the GUI input labelled ``label``."""
        uuid = next(u for u, lab in self.gui_label.items() if lab == label)
        self.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": {"value": value}})

    def value(self, label: str) -> Any:
        """Current value of the GUI input labelled ``label``, as last sent by the server."""
        uuid = next(u for u, lab in self.gui_label.items() if lab == label)
        return self.gui_value[uuid]

    def pump(self, timeout_s: float) -> list[dict[str, Any]]:
        """Receive one frame (waiting up to ``timeout_s``); apply and return its messages."""
        try:
            raw = self._ws.recv(timeout=timeout_s)
        except TimeoutError:
            return []
        stamp = time.perf_counter()
        assert isinstance(raw, bytes)
        size = int.from_bytes(raw[0:8], "little")
        csize = int.from_bytes(raw[8:16], "little")
        inner = self._dctx.decompress(raw[16 : 16 + csize], max_output_size=size)
        messages: list[dict[str, Any]] = msgspec.msgpack.decode(inner)["messages"]
        for m in messages:
            self._apply(m)
            self.received.append((stamp, m))
        return messages

    def pump_until(
        self, predicate: Callable[[PageClient], bool], *, timeout_s: float | None = None
    ) -> bool:
        """Receive until ``predicate(self)`` holds; False if the time runs out first."""
        deadline = time.monotonic() + (self._timeout_s if timeout_s is None else timeout_s)
        while not predicate(self):
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            self.pump(min(left, 0.5))
        return True

    def _apply(self, m: dict[str, Any]) -> None:
        kind = m.get("type", "")
        name = m.get("name")
        if isinstance(name, str):
            if "position" in m:
                self.positions[name] = tuple(m["position"])
            if "wxyz" in m:
                self.orientations[name] = tuple(m["wxyz"])
        if kind == "GuiUpdateMessage":
            updates = m.get("updates", {})
            if "value" in updates:
                self.gui_value[m["uuid"]] = updates["value"]
            self.gui_props.setdefault(m["uuid"], {}).update(updates)
        elif kind.startswith("Gui") and "uuid" in m and isinstance(m.get("props"), dict):
            props = m["props"]
            self.gui_props[m["uuid"]] = dict(props)
            if "label" in props:
                self.gui_label[m["uuid"]] = props["label"]
            if "value" in m:
                self.gui_value[m["uuid"]] = m["value"]


__all__ = ["PageClient"]
