"""The teach page: a viser server drawing a :class:`TeachSession` and wiring its events.

The arm is drawn from the same capsules as the MJCF/URDF models
(:func:`pipeline.robots.chain.chain`), or, for a robot loaded from a URDF, from its own
visual meshes (:mod:`pipeline.teach.meshes`), one node per link frame posed by forward
kinematics. A transform gizmo sets the flange target; joint sliders drive FK.
Every event goes through one lock (the solvers' Pinocchio data is not
thread-safe) and ends in :meth:`TeachServer.render`, which sends the new pose
and readout to every connected page and flushes.

viser serves its own prebuilt client from its wheel (``viser/client/build``):
nothing is fetched at run time.

Only the page itself may drive the server: a websocket whose ``Origin`` header is not
this server's own address (a page on another site, which the user's browser would let
connect to 127.0.0.1) is refused with 403 before its first message
(:mod:`pipeline.teach.origin`).
A handler that cannot act on what a client sent (a NaN pose, a value outside its range,
a file that cannot be written) tells that client in a notification, instead of printing
a traceback on the server's terminal.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import html
import io
import math
import socket
import threading
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np
import trimesh
import viser
from numpy.typing import ArrayLike, NDArray

from pipeline import transforms as tf
from pipeline.errors import PipelineError, TeachError
from pipeline.kinematics.check import (
    ORIENTATION_TARGET_RAD,
    POSITION_TARGET_M,
    TIME_TARGET_MS,
    sample_round_trips,
)
from pipeline.model.dh import link_frames
from pipeline.model.mjcf import FLOOR_Z_M
from pipeline.robots.chain import chain
from pipeline.teach.goal import GoalKind, goal_from_state, write_goal
from pipeline.teach.meshes import add_link_meshes
from pipeline.teach.origin import guard_incoming_messages, origin_checked_serve
from pipeline.teach.session import TeachSession, TeachState

Array = NDArray[np.float64]

TARGET_NODE = "/target"
"""Scene name of the flange-target gizmo (what a client's drag message names)."""
MARKER_NODE = "/target/marker"
ERROR_MAP_NODE = "/error_map"
ARM_ROOT = "/arm"
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
DEFAULT_MAP_SAMPLES = 300
MAX_MAP_SAMPLES = 20000
OK_RGB = (46, 160, 67)
BAD_RGB = (218, 54, 51)
_LINK_RGB = ((77, 128, 204), (204, 204, 204))
_OK_HTML, _BAD_HTML = "#2ea043", "#da3633"


def _told_to_client(handler: Callable[[Any, Any], None]) -> Callable[[Any, Any], None]:
    """A GUI/scene event handler that turns what it cannot do into a notification to the
    client that sent the event (a red one on that page), not a traceback on the server."""

    @functools.wraps(handler)
    def wrapped(self: Any, event: Any) -> None:
        try:
            handler(self, event)
        except Exception as err:  # bad input from a client is the client's to see
            client = getattr(event, "client", None)
            text = str(err) or type(err).__name__
            if client is not None:
                with contextlib.suppress(Exception):
                    client.add_notification("armlab teach", text, color="red")
                    return
            with contextlib.suppress(Exception):
                self._readout.content = (
                    f"<span style='color:{_BAD_HTML}'>{html.escape(text)}</span>"
                )

    return wrapped


def link_node(i: int) -> str:
    """Scene name of the node at link frame ``i`` (1..n; 0: the base): link i's geometry
    hangs on it."""
    return f"{ARM_ROOT}/link{i}"


def _capsule_mesh(spec_links: Sequence[Any], i: int, radius: float) -> trimesh.Trimesh:
    """Link i's capsules (or one sphere when it has no length), in link frame i [m]."""
    parts = []
    for seg in spec_links[i].segments:
        a, b = np.array(seg.start), np.array(seg.end)
        length = float(np.linalg.norm(b - a))
        cap = trimesh.creation.capsule(height=length, radius=seg.radius, count=[12, 12])
        pose = np.eye(4)
        pose[:3, :3] = _z_to(b - a)
        pose[:3, 3] = 0.5 * (a + b)
        cap.apply_transform(pose)
        parts.append(cap)
    if not parts:
        parts.append(trimesh.creation.icosphere(subdivisions=2, radius=radius))
    return cast(trimesh.Trimesh, trimesh.util.concatenate(parts))


def _z_to(direction: Array) -> Array:
    """A rotation taking the z axis onto ``direction``."""
    z = direction / np.linalg.norm(direction)
    helper = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def check_port_free(host: str, port: int) -> None:
    """Raise TeachError (one line, suggesting --port) if ``host:port`` cannot be bound.

    viser itself would silently move to the next free port; the user asked for this one.
    """
    if port == 0:
        return
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's server does
        try:
            sock.bind((host, port))
        except OSError as err:
            if err.errno == errno.EADDRINUSE:
                raise TeachError(
                    f"port {port} on {host} is already in use; pick another with --port N"
                ) from err
            raise TeachError(f"cannot listen on {host}:{port}: {err.strerror}") from err


def _fmt(value: float, unit: str, digits: int = 3) -> str:
    return "n/a" if math.isnan(value) else f"{value:.{digits}g} {unit}"


def _check_cell(ok: bool | None) -> str:
    if ok is None:
        return ""
    colour, word = (_OK_HTML, "pass") if ok else (_BAD_HTML, "FAIL")
    return f'<b style="color:{colour}">{word}</b>'


def readout_html(state: TeachState, *, solver: str) -> str:
    """The FK verification and arm-condition readout as an HTML fragment."""
    if state.reachable:
        if state.source == "ik":
            k = state.solutions.shape[0]
            which = f"solution {state.selected + 1} of {k}" + (
                " (nearest the previous pose)" if state.selected == 0 and k > 1 else ""
            )
            status = f'<b style="color:{_OK_HTML}">Solved</b> by {solver}: {which}'
        else:
            status = f'<b style="color:{_OK_HTML}">Joint sliders</b>: target follows the flange'
    else:
        status = (
            f'<b style="color:{_BAD_HTML}">Unreachable</b>: the arm keeps its last valid pose. '
            + html.escape(state.reason)
        )
    c = state.checks
    rows = [
        ("position error", _fmt(state.position_error_m * 1e3, "mm"), "&lt; 0.1 mm",
         c.get("position_error")),
        ("orientation error", _fmt(state.orientation_error_rad, "rad"),
         f"not judged: position-only IK ({state.q.size} joints)" if state.position_only
         else "&lt; 0.01 rad", c.get("orientation_error")),
        ("solve time", _fmt(state.solve_time_ms, "ms") if state.source == "ik" else "n/a (FK)",
         "&lt; 5 ms", c.get("solve_time")),
    ]  # fmt: skip
    table = "".join(
        f"<tr><td>{name}</td><td style='text-align:right'>{value}</td>"
        f"<td>{target}</td><td>{_check_cell(ok)}</td></tr>"
        for name, value, target, ok in rows
    )
    warn = (
        f'<br><b style="color:{_BAD_HTML}">Near a singularity</b>: smallest singular value '
        f"{state.min_singular_value:.3g} (joints may race)"
        if state.near_singular
        else ""
    )
    return (
        f"<div style='font-size:0.85em'>{status}"
        f"<table style='width:100%'>{table}</table>"
        f"manipulability {state.manipulability:.4g}, smallest singular value "
        f"{state.min_singular_value:.3g}{warn}</div>"
    )


def error_map_colours(
    position_error_m: Array, orientation_error_rad: Array, *, position_only: bool = False
) -> NDArray[np.uint8]:
    """Per sample: green far below the notes' targets, through yellow, to red at the target;
    red too for a sample IK did not solve. Log scale over six decades of the target. A
    position-only robot (fewer than 6 joints) is coloured by its position error alone."""
    ratio = position_error_m / POSITION_TARGET_M
    if not position_only:
        ratio = np.maximum(ratio, orientation_error_rad / ORIENTATION_TARGET_RAD)
    t = np.clip((np.log10(np.maximum(ratio, 1e-300)) + 6.0) / 6.0, 0.0, 1.0)
    t = np.where(np.isfinite(ratio), t, 1.0)
    green, yellow, red = np.array(OK_RGB), np.array((230, 200, 40)), np.array(BAD_RGB)
    lo = green + (yellow - green) * np.clip(2 * t, 0, 1)[:, None]
    out = np.where(
        (t <= 0.5)[:, None], lo, yellow + (red - yellow) * np.clip(2 * t - 1, 0, 1)[:, None]
    )
    return np.asarray(np.round(out), dtype=np.uint8)


class TeachServer:
    """A running teach page for one session.

    Args:
        session: the arm and its solver.
        robot_arg: the robot as the user named it (written into params goals).
        solver_note: why the solver is not the one asked for ("" if it is).
        host: interface to listen on (localhost by default).
        port: TCP port (0: any free port).
        params_path: default params file for "use as goal".

    Raises:
        TeachError: the port is in use or cannot be bound.
    """

    def __init__(
        self,
        session: TeachSession,
        *,
        robot_arg: str,
        solver_note: str = "",
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        params_path: str = "params.yaml",
    ) -> None:
        self.session = session
        self._spec = session.spec
        self._robot_arg = robot_arg
        self._solver_note = solver_note
        self._lock = threading.RLock()
        self._syncing = False
        check_port_free(host, port)
        guard_incoming_messages()  # a malformed message: one line, the session goes on
        with (
            contextlib.redirect_stdout(io.StringIO()),  # viser's banner; we print the URL
            origin_checked_serve(host) as built,
        ):
            self._server = viser.ViserServer(
                host=host, port=port, label=f"armlab teach: {self._spec.name}", verbose=False
            )
        if not built:  # fail closed: a viser that builds its server otherwise is unchecked
            self.close()
            raise TeachError(
                f"viser {viser.__version__} did not build its websocket server as expected; "
                "cannot check the Origin of connections, so the page is not served"
            )
        if port and self._server.get_port() != port:  # lost a race for the port
            self.close()
            raise TeachError(f"port {port} on {host} is already in use; pick another with --port N")
        self.host = host
        self.port = int(self._server.get_port())
        self.params_path = Path(params_path)
        self._build_scene()
        self._build_gui(params_path)
        self.render(session.state, move_target=True)

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    @property
    def state(self) -> TeachState:
        return self.session.state

    # ----- scene and GUI -------------------------------------------------------------------

    def _build_scene(self) -> None:
        scene = self._server.scene
        scene.set_up_direction("+z")
        scene.configure_environment_map(None)
        scene.add_grid("/floor", width=2.0, height=2.0, position=(0.0, 0.0, FLOOR_Z_M))
        scene.add_cylinder(
            "/pedestal", radius=0.08, height=-FLOOR_Z_M - 0.02, color=(100, 100, 100),
            position=(0.0, 0.0, 0.5 * (FLOOR_Z_M - 0.02)),
        )  # fmt: skip
        links = chain(self._spec)
        self._link_frames = []
        scene.add_frame(link_node(0), show_axes=False)
        # a URDF robot's own visual meshes; capsules for a DH robot (or unreadable meshes)
        self.meshes, self._mesh_note = add_link_meshes(scene, self._spec, link_node)
        for i, joint in enumerate(self._spec.joints, start=1):
            frame = scene.add_frame(link_node(i), show_axes=False)
            self._link_frames.append(frame)
            if self.meshes:
                continue
            mesh = _capsule_mesh(links, i - 1, joint.collision_radius)
            scene.add_mesh_simple(
                f"{link_node(i)}/geom", vertices=np.asarray(mesh.vertices, dtype=np.float32),
                faces=np.asarray(mesh.faces, dtype=np.uint32), color=_LINK_RGB[(i - 1) % 2],
            )  # fmt: skip
        scene.add_frame(f"{link_node(self._spec.dof)}/flange", axes_length=0.08, axes_radius=0.004)
        self._gizmo = scene.add_transform_controls(TARGET_NODE, scale=0.2, depth_test=False)
        self._marker = scene.add_icosphere(MARKER_NODE, radius=0.015, color=OK_RGB)
        self._gizmo.on_update(self._on_gizmo)
        reach = self._spec.reach_m()
        self._server.initial_camera.position = (1.1 * reach, -1.1 * reach, 0.75 * reach)
        self._server.initial_camera.look_at = (0.0, 0.15 * reach, 0.1 * reach)

    def _build_gui(self, params_path: str) -> None:
        gui = self._server.gui
        spec = self._spec
        solver = self.session.solver.name
        note = (
            f"<br><b style='color:#d29922'>Numeric IK</b>: {html.escape(self._solver_note)}"
            if self._solver_note
            else ""
        )
        if self._mesh_note:  # a URDF robot whose meshes could not be read
            note += f"<br><b style='color:#d29922'>Meshes</b>: {html.escape(self._mesh_note)}"
        gui.add_html(
            f"<div style='font-size:0.85em'><b>{html.escape(spec.name)}</b>, {spec.dof} joints, "
            f"IK <b>{solver}</b>. Drag the gizmo to set the flange target.{note}</div>"
        )
        self._readout = gui.add_html("")
        self._solutions = gui.add_dropdown("IK solution", options=("1",), initial_value="1")
        self._solutions.on_update(self._on_solution)
        with gui.add_folder("Joints [rad] (FK)"):
            self._sliders = []
            self._bars = []
            for joint, q in zip(spec.joints, self.state.q, strict=True):
                lim = joint.limits
                # the session's start (0 may be outside a joint's limits, e.g. the Panda's 4th)
                slider = gui.add_slider(
                    joint.name, min=lim.lower, max=lim.upper, step=1e-3, initial_value=float(q)
                )
                slider.on_update(self._on_slider)
                self._sliders.append(slider)
                self._bars.append(gui.add_progress_bar(50.0, color="blue"))
        with gui.add_folder("IK error map", expand_by_default=False):
            self._map_samples = gui.add_number(
                "samples", initial_value=DEFAULT_MAP_SAMPLES, min=10, max=MAX_MAP_SAMPLES, step=10
            )
            show = gui.add_button("Show error map")
            hide = gui.add_button("Hide error map")
            self._map_status = gui.add_html("")
            show.on_click(self._on_show_map)
            hide.on_click(self._on_hide_map)
        with gui.add_folder("Use as goal", expand_by_default=False):
            # shown, not chosen: teach writes only the file it was started with (--params)
            self._goal_path = gui.add_text("params file", initial_value=params_path, disabled=True)
            self._goal_scenario = gui.add_text("scenario", initial_value="taught")
            self._goal_kind = gui.add_dropdown(
                "goal as", options=("pose", "joints"), initial_value="pose"
            )
            write = gui.add_button("Write goal")
            self._goal_status = gui.add_html("")
            write.on_click(self._on_write_goal_click)

    # ----- events ----------------------------------------------------------------------------

    @_told_to_client
    def _on_gizmo(self, event: Any) -> None:
        if getattr(event, "phase", "update") == "start":
            return
        self.update_target(self._gizmo.position, self._gizmo.wxyz)

    @_told_to_client
    def _on_slider(self, _: Any) -> None:
        if self._syncing:
            return
        self.update_joints([s.value for s in self._sliders])

    @_told_to_client
    def _on_solution(self, _: Any) -> None:
        if self._syncing:
            return
        with self._lock:
            value = str(self._solutions.value)
            head = value.split()[0] if value.split() else ""
            count = self.state.solutions.shape[0] if self.state.reachable else 0
            if not head.isdigit() or not 1 <= int(head) <= count:
                raise TeachError(f"IK solution {value!r}: expected one of 1..{count}")
            index = int(head) - 1
            if index != self.state.selected:
                self.render(self.session.select_solution(index), move_target=False)

    @_told_to_client
    def _on_show_map(self, _: Any) -> None:
        samples = self._map_samples.value
        if not isinstance(samples, int | float) or not 10 <= samples <= MAX_MAP_SAMPLES:
            raise TeachError(f"samples {samples!r}: expected 10..{MAX_MAP_SAMPLES}")
        self.show_error_map(int(samples))

    @_told_to_client
    def _on_hide_map(self, _: Any) -> None:
        self.hide_error_map()

    @_told_to_client
    def _on_write_goal_click(self, _: Any) -> None:
        self._on_write_goal()

    def _on_write_goal(self) -> None:
        try:
            if str(self._goal_path.value) != str(self.params_path):
                raise TeachError(
                    f"params file {str(self._goal_path.value)!r:.200}: teach writes only the "
                    f"file it was started with ({self.params_path}; restart with --params)"
                )
            path = self.write_goal(
                self.params_path, scenario=str(self._goal_scenario.value).strip(),
                kind="joints" if self._goal_kind.value == "joints" else "pose",
            )  # fmt: skip
        except PipelineError as err:
            self._goal_status.content = (
                f"<span style='color:{_BAD_HTML}'>{html.escape(str(err))}</span>"
            )
        else:
            self._goal_status.content = (
                f"<span style='color:{_OK_HTML}'>wrote scenarios."
                f"{html.escape(self._goal_scenario.value.strip())}.goal to "
                f"{html.escape(str(path))} (validated)</span>"
            )

    # ----- the update path (also what tests and the benchmark drive) -----------------------

    def update_target(self, position_m: ArrayLike, wxyz: ArrayLike) -> TeachState:
        """A new flange target (position [m], quaternion w x y z): solve IK, draw, send."""
        target = np.eye(4)
        q = np.asarray(wxyz, dtype=float)
        p = np.asarray(position_m, dtype=float)
        if (
            q.shape != (4,)
            or p.shape != (3,)
            or not (np.isfinite(q).all() and np.isfinite(p).all())
        ):
            raise TeachError(
                f"target: expected a finite position (3) and quaternion (4), got {p} {q}"
            )
        scale = float(np.abs(q).max())
        if scale == 0.0:
            raise TeachError("target: a zero quaternion has no orientation")
        q = q / scale  # (a huge quaternion would overflow the norm)
        target[:3, :3] = tf.quat_to_matrix(q / np.linalg.norm(q))
        target[:3, 3] = p
        with self._lock:
            state = self.session.set_target(target)
            self.render(state, move_target=False)
            return state

    def update_joints(self, q: ArrayLike) -> TeachState:
        """New joint values [rad] (FK): the arm moves and the gizmo follows the flange."""
        with self._lock:
            try:
                state = self.session.set_joints(q)
            except PipelineError as err:  # a slider cannot leave its range; keep the pose
                self._readout.content = html.escape(str(err))
                return self.state
            self.render(state, move_target=True)
            return state

    def render(self, state: TeachState, *, move_target: bool) -> None:
        """Send ``state`` to every page: arm pose, target marker, readout, sliders; flush."""
        with self._lock, self._server.atomic():
            for frame, base_T_i in zip(
                self._link_frames, link_frames(self._spec, state.q), strict=True
            ):
                frame.position = base_T_i[:3, 3]
                frame.wxyz = tf.quat_wxyz(base_T_i[:3, :3])
            if move_target:
                self._gizmo.position = state.target[:3, 3]
                self._gizmo.wxyz = tf.quat_wxyz(state.target[:3, :3])
            self._marker.color = OK_RGB if state.reachable else BAD_RGB
            self._readout.content = readout_html(state, solver=self.session.solver.name)
            self._syncing = True
            try:
                if state.reachable:
                    k = state.solutions.shape[0]
                    options = tuple(f"{i + 1} of {k}" for i in range(k))
                    self._solutions.options = options
                    # viser's value setters are typed read-only for mypy (asymmetric property)
                    self._solutions.value = options[state.selected]  # type: ignore[misc]
                for slider, value in zip(self._sliders, state.q.tolist(), strict=True):
                    slider.value = value  # type: ignore[misc]
            finally:
                self._syncing = False
            near = state.near_limit(self._spec)
            for bar, frac, close in zip(
                self._bars, state.joint_fraction(self._spec), near, strict=True
            ):
                bar.value = float(np.clip(100.0 * frac, 0.0, 100.0))  # type: ignore[misc]
                bar.color = "red" if close else "blue"
        self._server.flush()

    # ----- on request ------------------------------------------------------------------------

    def show_error_map(self, samples: int = DEFAULT_MAP_SAMPLES, *, seed: int = 0) -> int:
        """Run the ik-check round trip and draw each sample's flange position, coloured by
        its worst error relative to the notes' targets. Returns how many samples failed."""
        self._map_status.content = f"running {samples} FK -> IK -> FK round trips..."
        with self._lock:
            trips = sample_round_trips(
                self._spec, solver_name=self.session.solver.name, samples=samples, seed=seed
            )
        colours = error_map_colours(
            trips.position_error_m, trips.orientation_error_rad, position_only=trips.position_only
        )
        self._server.scene.add_point_cloud(
            ERROR_MAP_NODE, points=trips.flange_position_m.astype(np.float32), colors=colours,
            point_size=0.012, point_shape="circle",
        )  # fmt: skip
        failed = int((~trips.good).sum())
        p99 = float(np.percentile(trips.time_ms, 99))
        self._map_status.content = (
            f"<div style='font-size:0.85em'>{samples} samples, {failed} failed; "
            f"p99 solve {p99:.3g} ms (target &lt; {TIME_TARGET_MS:g}). Colour: worst error "
            "relative to the target, green (1e-6 of it) to red (at or above it, or unsolved)"
            "</div>"
        )
        self._server.flush()
        return failed

    def hide_error_map(self) -> None:
        self._server.scene.remove_by_name(ERROR_MAP_NODE)
        self._map_status.content = ""

    def write_goal(self, params_path: Path, *, scenario: str, kind: GoalKind) -> Path:
        """Write the shown pose (or joints) as ``scenarios.<scenario>.goal`` (validated, atomic).

        Raises:
            TeachError: ``params_path`` is not the file the server was started with.
        """
        if Path(params_path).absolute() != self.params_path.absolute():
            raise TeachError(
                f"{params_path}: teach writes only the file it was started with "
                f"({self.params_path})"
            )
        with self._lock:
            goal = goal_from_state(self.state, kind=kind, solver=self.session.solver.name)
            write_goal(
                params_path, scenario=scenario, robot=self._robot_arg, spec=self._spec, goal=goal
            )
        return params_path

    def close(self) -> None:
        """Stop the server and its threads (quietly: viser prints 'Server stopped')."""
        with contextlib.redirect_stdout(io.StringIO()):
            self._server.stop()


__all__ = [
    "DEFAULT_HOST",
    "DEFAULT_PORT",
    "TARGET_NODE",
    "TeachServer",
    "check_port_free",
    "error_map_colours",
    "link_node",
    "readout_html",
]
