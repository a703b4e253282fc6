"""Vectorized CDR encoders for the fixed-layout messages of a recording.

ROS 2 serializes messages as little-endian plain CDR (XCDR1): a 4-byte encapsulation header
``00 01 00 00``, then the fields, each aligned to its own size (float64: 8, int32/uint32 and
sequence/string lengths: 4) relative to the byte *after* the header; a string is a uint32
length that counts its NUL, the UTF-8 bytes and the NUL; a sequence is a uint32 count then its
elements (an empty float64 sequence adds no alignment padding).

For a given joint-name list (and fixed sequence lengths) a message's layout never changes, so
we lay out one message with :class:`CdrWriter`, remember where the per-message values go
(:class:`Template` slots), and fill N copies at once with numpy: no per-message Python work.
Generic encoders (mcap_ros2's) cost tens of microseconds per message; this costs well under
one (see ``benches/log_encode.py``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

ENCAPSULATION_CDR_LE = b"\x00\x01\x00\x00"
_NS_PER_S = 1_000_000_000

U8 = NDArray[np.uint8]


class CdrWriter:
    """Appends CDR fields to a buffer, and records named slots to fill later.

    Args:
        header: start with the encapsulation header (a whole message); without it the writer
            produces a fragment that is appended to a message at body offset ``origin``.
        origin: body offset (after the header) at which a fragment starts [bytes].
    """

    def __init__(self, *, header: bool = True, origin: int = 0) -> None:
        self._buf = bytearray(ENCAPSULATION_CDR_LE if header else b"")
        self._shift = origin - (4 if header else 0)
        self.slots: dict[str, tuple[int, int]] = {}

    @property
    def body_offset(self) -> int:
        """Bytes written after the encapsulation header (plus ``origin`` for fragments)."""
        return len(self._buf) + self._shift

    def align(self, size: int) -> None:
        """Pad to a multiple of ``size`` bytes, counted after the encapsulation header."""
        self._buf += b"\x00" * (-self.body_offset % size)

    def raw(self, data: bytes) -> None:
        """Append already encoded bytes (a fragment laid out for this offset)."""
        self._buf += data

    def _slot(self, name: str | None, offset: int, nbytes: int) -> None:
        if name is not None:
            if name in self.slots:
                raise ValueError(f"duplicate CDR slot {name!r}")
            self.slots[name] = (offset, nbytes)

    def uint32(self, value: int) -> None:
        self.align(4)
        self._buf += int(value).to_bytes(4, "little")

    def time(self, stamp_ns: int = 0, *, slot: str | None = None) -> None:
        """builtin_interfaces Time/Duration: int32 sec, uint32 nanosec (floor division)."""
        self.align(4)
        self._slot(slot, len(self._buf), 8)
        self._buf += stamp_pairs(np.array([stamp_ns])).tobytes()

    def string(self, text: str) -> None:
        data = text.encode("utf-8")
        self.uint32(len(data) + 1)
        self._buf += data + b"\x00"

    def strings(self, items: Sequence[str]) -> None:
        self.uint32(len(items))
        for item in items:
            self.string(item)

    def float64s(self, values: ArrayLike, *, slot: str | None = None) -> None:
        """A fixed-size float64 array (e.g. the fields of a Vector3), no length prefix."""
        arr = np.ascontiguousarray(values, dtype="<f8").reshape(-1)
        if arr.size:
            self.align(8)
        self._slot(slot, len(self._buf), 8 * arr.size)
        self._buf += arr.tobytes()

    def float64_seq(self, values: ArrayLike, *, slot: str | None = None) -> None:
        """A float64 sequence: uint32 count, then (8-aligned if non-empty) the values."""
        arr = np.ascontiguousarray(values, dtype="<f8").reshape(-1)
        self.uint32(arr.size)
        self.float64s(arr, slot=slot)

    def getvalue(self) -> bytes:
        return bytes(self._buf)

    def template(self) -> Template:
        return Template(np.frombuffer(self.getvalue(), dtype=np.uint8), dict(self.slots))


@dataclass(frozen=True)
class Template:
    """One encoded message plus the byte ranges (offset, length) that vary per message."""

    data: U8
    slots: Mapping[str, tuple[int, int]]

    @property
    def size(self) -> int:
        return int(self.data.size)

    def fill(self, count: int, values: Mapping[str, NDArray[np.generic]]) -> U8:
        """``count`` messages as a (count, size) byte matrix, slot rows taken from ``values``.

        Each value is an array with ``count`` rows whose row bytes equal the slot length
        (e.g. (count, n) float64 for an n-element float64 slot); slots not given keep the
        template bytes.
        """
        out = np.empty((count, self.size), dtype=np.uint8)
        out[:] = self.data
        for name, arr in values.items():
            offset, nbytes = self.slots[name]
            flat = np.ascontiguousarray(arr).view(np.uint8).reshape(-1)
            if flat.size != count * nbytes:
                raise ValueError(f"slot {name!r}: {flat.size} bytes for {count}x{nbytes}")
            out[:, offset : offset + nbytes] = flat.reshape(count, nbytes)
        return out


def stamp_pairs(stamp_ns: ArrayLike) -> NDArray[np.uint32]:
    """(N, 2) uint32 (sec, nanosec) of int64 nanosecond times, nanosec in [0, 1e9).

    ``sec`` is an int32 on the wire; its two's complement bits are stored.
    """
    ns = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
    sec, nsec = np.divmod(ns, _NS_PER_S)
    if ns.size and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError("time does not fit builtin_interfaces int32 seconds")
    out = np.empty((ns.size, 2), dtype=np.uint32)
    out[:, 0] = sec.astype(np.int32).view(np.uint32)
    out[:, 1] = nsec.astype(np.uint32)
    return out


def _f64(values: ArrayLike, count: int, width: int, what: str) -> NDArray[np.float64]:
    arr = np.ascontiguousarray(values, dtype="<f8")
    if arr.shape != (count, width):
        raise ValueError(f"{what}: shape {arr.shape}, expected {(count, width)}")
    return arr


# --- sensor_msgs/msg/JointState -----------------------------------------------------------


@functools.lru_cache(maxsize=32)
def joint_state_template(joint_names: tuple[str, ...]) -> Template:
    """header (stamp, frame_id ""), name, position, velocity, effort (all ``len(names)``)."""
    n = len(joint_names)
    w = CdrWriter()
    w.time(slot="stamp")
    w.string("")
    w.strings(joint_names)
    w.float64_seq(np.zeros(n), slot="position")
    w.float64_seq(np.zeros(n), slot="velocity")
    w.float64_seq(np.zeros(n), slot="effort")
    return w.template()


def encode_joint_states(
    joint_names: Sequence[str],
    stamp_ns: ArrayLike,
    *,
    position: ArrayLike,
    velocity: ArrayLike,
    effort: ArrayLike,
) -> U8:
    """N JointState messages as an (N, L) byte matrix (row k = CDR bytes of message k)."""
    names = tuple(joint_names)
    stamps = stamp_pairs(stamp_ns)
    count, n = stamps.shape[0], len(names)
    return joint_state_template(names).fill(
        count,
        {
            "stamp": stamps,
            "position": _f64(position, count, n, "position"),
            "velocity": _f64(velocity, count, n, "velocity"),
            "effort": _f64(effort, count, n, "effort"),
        },
    )


# --- control_msgs/msg/JointTrajectoryControllerState (Jazzy) ------------------------------

# Which JointTrajectoryPoint fields each point of the controller state carries; the others are
# empty sequences (as ros2_controllers' JTC leaves them).
_CS_POINT_FIELDS: dict[str, tuple[str, ...]] = {
    "reference": ("positions", "velocities", "accelerations"),
    "feedback": ("positions", "velocities"),
    "error": ("positions", "velocities"),
    "output": ("effort",),
}
_POINT_SEQUENCES = ("positions", "velocities", "accelerations", "effort")


@functools.lru_cache(maxsize=32)
def controller_state_template(joint_names: tuple[str, ...]) -> Template:
    n = len(joint_names)
    w = CdrWriter()
    w.time(slot="stamp")
    w.string("")
    w.strings(joint_names)
    for point, fields in _CS_POINT_FIELDS.items():
        for seq in _POINT_SEQUENCES:
            if seq in fields:
                w.float64_seq(np.zeros(n), slot=f"{point}.{seq}")
            else:
                w.float64_seq(np.zeros(0))
        w.time(slot=f"{point}.time_from_start")
    w.strings(())  # multi_dof_joint_names
    for _ in range(4):  # multi_dof_reference, _feedback, _error, _output: empty points
        for _seq in range(3):  # transforms, velocities, accelerations
            w.uint32(0)
        w.time(0)
    return w.template()


def encode_controller_states(
    joint_names: Sequence[str],
    stamp_ns: ArrayLike,
    *,
    reference: tuple[ArrayLike, ArrayLike, ArrayLike],
    feedback: tuple[ArrayLike, ArrayLike],
    error: tuple[ArrayLike, ArrayLike],
    output_effort: ArrayLike,
    time_from_start_ns: ArrayLike,
) -> U8:
    """N JointTrajectoryControllerState messages as an (N, L) byte matrix.

    Args:
        reference: (positions, velocities, accelerations), each (N, n).
        feedback: (positions, velocities), each (N, n).
        error: (positions, velocities), each (N, n).
        output_effort: (N, n) commanded effort.
        time_from_start_ns: (N,) time along the trajectory, written to every point [ns].
    """
    names = tuple(joint_names)
    stamps = stamp_pairs(stamp_ns)
    count, n = stamps.shape[0], len(names)
    tfs = stamp_pairs(time_from_start_ns)
    if tfs.shape[0] != count:
        raise ValueError("time_from_start_ns: one value per message expected")
    values: dict[str, NDArray[np.generic]] = {"stamp": stamps}
    given = {
        "reference": reference,
        "feedback": feedback,
        "error": error,
        "output": (output_effort,),
    }
    for point, fields in _CS_POINT_FIELDS.items():
        for seq, arr in zip(fields, given[point], strict=True):
            values[f"{point}.{seq}"] = _f64(arr, count, n, f"{point}.{seq}")
        values[f"{point}.time_from_start"] = tfs
    return controller_state_template(names).fill(count, values)


# --- tf2_msgs/msg/TFMessage ---------------------------------------------------------------


@functools.lru_cache(maxsize=32)
def tf_template(frames: tuple[tuple[str, str], ...]) -> Template:
    """TFMessage with one TransformStamped per (parent, child) frame pair."""
    w = CdrWriter()
    w.uint32(len(frames))
    for i, (parent, child) in enumerate(frames):
        w.time(slot=f"stamp{i}")
        w.string(parent)
        w.string(child)
        # translation (x, y, z) and rotation (x, y, z, w): 7 contiguous 8-aligned float64
        w.float64s(np.zeros(7), slot=f"transform{i}")
    return w.template()


def encode_tf(
    frames: Sequence[tuple[str, str]],
    stamp_ns: ArrayLike,
    *,
    translation: ArrayLike,
    rotation_xyzw: ArrayLike,
) -> U8:
    """M TFMessage messages as an (M, L) byte matrix.

    Args:
        frames: E (parent frame_id, child_frame_id) pairs, the same in every message.
        stamp_ns: (M,) header stamps [ns], shared by the E transforms of a message.
        translation: (M, E, 3) [m].
        rotation_xyzw: (M, E, 4) unit quaternions in ROS order (x, y, z, w).
    """
    key = tuple((str(p), str(c)) for p, c in frames)
    stamps = stamp_pairs(stamp_ns)
    count, edges = stamps.shape[0], len(key)
    t = np.asarray(translation, dtype="<f8")
    r = np.asarray(rotation_xyzw, dtype="<f8")
    if t.shape != (count, edges, 3) or r.shape != (count, edges, 4):
        raise ValueError(f"translation/rotation shapes {t.shape}/{r.shape} for {count}x{edges}")
    pose = np.concatenate([t, r], axis=2)
    values: dict[str, NDArray[np.generic]] = {}
    for i in range(edges):
        values[f"stamp{i}"] = stamps
        values[f"transform{i}"] = np.ascontiguousarray(pose[:, i, :])
    return tf_template(key).fill(count, values)


# --- one-off messages ---------------------------------------------------------------------


def encode_string(text: str) -> bytes:
    """std_msgs/msg/String."""
    w = CdrWriter()
    w.string(text)
    return w.getvalue()


def encode_joint_trajectory(
    joint_names: Sequence[str],
    stamp_ns: int,
    *,
    time_from_start_ns: ArrayLike,
    positions: ArrayLike,
    velocities: ArrayLike,
    accelerations: ArrayLike,
) -> bytes:
    """trajectory_msgs/msg/JointTrajectory with K points (effort left empty).

    Args:
        stamp_ns: header stamp [ns].
        time_from_start_ns: (K,) [ns].
        positions, velocities, accelerations: (K, n).
    """
    tfs = np.asarray(time_from_start_ns, dtype=np.int64).reshape(-1)
    count, n = tfs.size, len(joint_names)
    pos = _f64(positions, count, n, "positions")
    vel = _f64(velocities, count, n, "velocities")
    acc = _f64(accelerations, count, n, "accelerations")
    w = CdrWriter()
    w.time(stamp_ns)
    w.string("")
    w.strings(list(joint_names))
    w.uint32(count)
    # A point's layout depends only on the 8-byte phase it starts at (its fields are 4- or
    # 8-aligned), so lay out one point per phase and fill all points of a phase at once.
    phases = np.empty(count, dtype=np.int64)
    phase = w.body_offset % 8
    for k in range(count):
        phases[k] = phase
        phase = (phase + _point_template(n, phase).size) % 8
    rows = np.empty(count, dtype=object)
    for phase in np.unique(phases).tolist():
        sel = phases == phase
        filled = _point_template(n, phase).fill(
            int(sel.sum()),
            {
                "positions": pos[sel],
                "velocities": vel[sel],
                "accelerations": acc[sel],
                "t": stamp_pairs(tfs[sel]),
            },
        )
        rows[sel] = [row.tobytes() for row in filled]
    w.raw(b"".join(rows.tolist()))
    return w.getvalue()


@functools.lru_cache(maxsize=16)
def _point_template(n: int, phase: int) -> Template:
    """A JointTrajectoryPoint fragment (n positions/velocities/accelerations, no effort)."""
    w = CdrWriter(header=False, origin=phase)
    w.float64_seq(np.zeros(n), slot="positions")
    w.float64_seq(np.zeros(n), slot="velocities")
    w.float64_seq(np.zeros(n), slot="accelerations")
    w.float64_seq(np.zeros(0))
    w.time(slot="t")
    return w.template()
