"""The reader on legal-but-unusual recordings: other schema names, missing fields,
decimated /joint_states, wall-clock stamps; and its one-exception-type boundary."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

import pipeline.log.decode as decode
from pipeline.errors import RecordingError
from pipeline.log.reader import read_recording
from tests.analysis.bagfactory import mcap_file, msgdef, paper_like, write_bag

JOINT_STATE = "sensor_msgs/msg/JointState"


def test_ros1_style_schema_name_reads_the_same_as_the_ros2_name(tmp_path: Path) -> None:
    ep = paper_like("names", "pid", duration_s=0.3, motion_end_s=0.2)
    reference = read_recording(write_bag(tmp_path / "a", ep))
    ep.joint_state_msgdef = ("sensor_msgs/JointState", msgdef(JOINT_STATE))
    variant = read_recording(write_bag(tmp_path / "b", ep))
    assert variant.samples.equals(reference.samples)
    assert variant.controller_states.equals(reference.controller_states)


def test_schema_without_a_header_stamp_is_one_line_naming_file_topic_and_field(
    tmp_path: Path,
) -> None:
    ep = paper_like("nostamp", "pid", duration_s=0.3, motion_end_s=0.2)
    ep.joint_state_msgdef = (
        JOINT_STATE,
        "string[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    )
    path = write_bag(tmp_path, ep)
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(mcap_file(path)) in message
    assert "/joint_states" in message and "header.stamp" in message


def test_schema_without_positions_is_refused_naming_the_field(tmp_path: Path) -> None:
    ep = paper_like("nopos", "pid", duration_s=0.3, motion_end_s=0.2)
    ep.joint_state_msgdef = (
        JOINT_STATE,
        "std_msgs/Header header\nstring[] name\nfloat64[] velocity\nfloat64[] effort\n"
        "================================================================================\n"
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
    )
    with pytest.raises(RecordingError, match=r"/joint_states .* has no field position"):
        read_recording(write_bag(tmp_path, ep))


def test_an_unforeseen_decoder_failure_is_a_recording_error_naming_file_and_topic(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = write_bag(tmp_path, paper_like("bug", "pid", duration_s=0.2, motion_end_s=0.1))

    def broken(*args: object, **kwargs: object) -> None:
        raise IndexError("index 7 is out of bounds")

    monkeypatch.setattr(decode, "_leaf_matrix", broken)
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert str(mcap_file(path)) in message and "cannot decode /" in message
    assert "IndexError" in message
    assert isinstance(info.value.__cause__, IndexError)


def test_controller_states_keep_the_full_rate_when_joint_states_are_decimated(
    tmp_path: Path,
) -> None:
    ep = paper_like("dec", "pid", duration_s=0.5, motion_end_s=0.3, period_s=1e-3)
    ep.joint_state_every = 4
    path = write_bag(tmp_path, ep)
    rec = read_recording(path)
    # Independent decode of every /controller_state message.
    with open(mcap_file(path), "rb") as fh:
        msgs = [
            m
            for _, _, _, m in make_reader(
                fh, decoder_factories=[DecoderFactory()]
            ).iter_decoded_messages(topics=["/controller_state"], log_time_order=True)
        ]
    n = len(rec.joint_names)
    stamps = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs])
    cs = rec.controller_states
    np.testing.assert_array_equal(cs.get_column("stamp_ns").to_numpy()[::n], stamps)
    for column, field in (
        ("error_rad", "error"),
        ("reference_position_rad", "reference"),
        ("feedback_position_rad", "feedback"),
    ):
        expected = np.array([getattr(m, field).positions for m in msgs])
        np.testing.assert_array_equal(cs.get_column(column).to_numpy().reshape(-1, n), expected)
    assert cs.height == len(ep.stamp_ns) * n
    assert rec.samples.height == len(ep.stamp_ns[::4]) * n
    np.testing.assert_array_equal(
        rec.samples.get_column("stamp_ns").to_numpy()[::n], ep.stamp_ns[::4]
    )


def test_times_count_from_the_first_stamp_and_stamps_stay_absolute(tmp_path: Path) -> None:
    ep = paper_like("wall", "pid", duration_s=0.4, motion_end_s=0.2)
    offset = 1_700_000_000_987_654_321
    ep.stamp_ns = ep.stamp_ns + offset
    rec = read_recording(write_bag(tmp_path, ep))
    n = len(rec.joint_names)
    for frame in (rec.samples, rec.controller_states):
        stamps = frame.get_column("stamp_ns").to_numpy()[::n]
        np.testing.assert_array_equal(stamps, ep.stamp_ns)
        # Exact to the nanosecond: the subtraction happens in integers.
        np.testing.assert_allclose(
            frame.get_column("time_s").to_numpy()[::n], (ep.stamp_ns - offset) * 1e-9, atol=1e-15
        )


def test_missing_episode_metadata_is_noted(tmp_path: Path) -> None:
    ep = paper_like("nometa", "pid", duration_s=0.2, motion_end_s=0.1)
    ep.episode_metadata = False
    rec = read_recording(write_bag(tmp_path, ep))
    assert rec.episode == "nometa"  # from the folder name
    assert any("no 'armlab.episode' metadata record" in note for note in rec.notes)
