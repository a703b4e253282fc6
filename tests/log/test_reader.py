"""The recording reader: fast path vs mcap_ros2's decoder, file variants, damaged files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import polars as pl
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType
from mcap_ros2.decoder import DecoderFactory

from pipeline.errors import RecordingError
from pipeline.log.cdr import walk as message_layout
from pipeline.log.msgdef import parse_msgdef
from pipeline.log.reader import find_recordings, read_recording
from tests.analysis.bagfactory import (
    JTCS,
    damage,
    first_chunk,
    first_chunk_records,
    flip_byte,
    mcap_file,
    msgdef,
    paper_like,
    write_bag,
)


def _expected(path: Path) -> dict[str, np.ndarray]:
    """Decode the control-rate topics with mcap_ros2 (independent of our reader)."""
    js: dict[str, list] = {"t": [], "position": [], "velocity": [], "effort": []}
    cs: dict[str, list] = {"t": [], "ref": [], "refv": [], "err": [], "cmd": []}
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        decoded = [
            (channel.topic, msg)
            for _, channel, _, msg in reader.iter_decoded_messages(
                topics=["/joint_states", "/controller_state"], log_time_order=True
            )
        ]
    for topic, msg in decoded:
        t = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if topic == "/joint_states":
            js["t"].append(t)
            js["position"].append(msg.position)
            js["velocity"].append(msg.velocity)
            js["effort"].append(msg.effort)
        else:
            cs["t"].append(t)
            cs["ref"].append(msg.reference.positions)
            cs["refv"].append(msg.reference.velocities)
            cs["err"].append(msg.error.positions)
            cs["cmd"].append(msg.output.effort)
    assert js["t"] == cs["t"]
    return {
        "stamp_ns": np.array(js["t"]),
        "position_rad": np.array(js["position"]),
        "velocity_rad_s": np.array(js["velocity"]),
        "effort_nm": np.array(js["effort"]),
        "reference_position_rad": np.array(cs["ref"]),
        "reference_velocity_rad_s": np.array(cs["refv"]),
        "error_rad": np.array(cs["err"]),
        "commanded_effort_nm": np.array(cs["cmd"]),
    }


def _assert_same_as_mcap_ros2(recording: Path) -> None:
    rec = read_recording(recording)
    expected = _expected(mcap_file(recording))
    n = len(rec.joint_names)
    got_t = rec.samples.get_column("stamp_ns").to_numpy()[::n]
    np.testing.assert_array_equal(got_t, expected["stamp_ns"])
    for column, values in expected.items():
        if column == "stamp_ns":
            continue
        got = rec.samples.get_column(column).to_numpy().reshape(-1, n)
        # Bit-for-bit: both decoders read the same IEEE doubles.
        np.testing.assert_array_equal(got, values, err_msg=column)


def test_fast_path_equals_mcap_ros2_decoder_field_by_field(tmp_path: Path) -> None:
    ep = paper_like("pid_a", "pid", duration_s=1.0)
    _assert_same_as_mcap_ros2(write_bag(tmp_path, ep))


def test_messages_of_varying_length_decode_the_same_through_the_slow_path(tmp_path: Path) -> None:
    ep = paper_like("pid_b", "pid", duration_s=0.4)
    # header.frame_id changes length message to message: no shared layout.
    ep.frame_ids = ["" if k % 3 else "base_link" * (k % 5) for k in range(len(ep.stamp_ns))]
    _assert_same_as_mcap_ros2(write_bag(tmp_path, ep))


@pytest.mark.parametrize(
    "options",
    [
        {"index_types": IndexType.NONE},
        {"use_chunking": False},
        {"enable_data_crcs": True},
    ],
    ids=["no-message-index", "unchunked", "data-crc"],
)
def test_file_layout_variants_read_the_same(tmp_path: Path, options: dict) -> None:
    ep = paper_like("ctc_v", "ctc", duration_s=0.6)
    reference = read_recording(write_bag(tmp_path / "a", ep)).samples
    variant = read_recording(write_bag(tmp_path / "b", ep, mcap_options=options)).samples
    assert variant.equals(reference)


@pytest.mark.parametrize("compression", [CompressionType.LZ4, CompressionType.NONE])
def test_compression_variants_read_the_same(tmp_path: Path, compression: CompressionType) -> None:
    ep = paper_like("ctc_c", "ctc", duration_s=0.6)
    reference = read_recording(write_bag(tmp_path / "a", ep)).samples
    variant = read_recording(write_bag(tmp_path / "b", ep, compression=compression)).samples
    assert variant.equals(reference)


def test_bare_mcap_file_is_a_recording(tmp_path: Path) -> None:
    ep = paper_like("bare", "pid", duration_s=0.3)
    path = write_bag(tmp_path, ep, as_directory=False)
    rec = read_recording(path)
    assert rec.episode == "bare" and rec.mcap_path == path
    assert rec.samples.height == len(ep.stamp_ns) * 6


def test_recording_carries_metadata_planned_trajectory_and_hash(tmp_path: Path) -> None:
    import hashlib

    ep = paper_like("pid_m", "pid", duration_s=1.5, motion_end_s=1.0)
    path = write_bag(tmp_path, ep)
    rec = read_recording(path)
    assert (rec.controller, rec.scenario, rec.robot) == ("pid", "paper", "ur5")
    assert rec.sha256 == hashlib.sha256(mcap_file(path).read_bytes()).hexdigest()
    assert rec.trajectory_duration_s == 1.0
    assert rec.planned is not None and rec.planned.positions.shape == (5, 6)
    np.testing.assert_allclose(rec.planned.times_s[-1], 1.0)
    assert rec.topic_counts["/joint_states"] == len(ep.stamp_ns)
    assert list(rec.samples.columns)[:4] == ["episode", "stamp_ns", "time_s", "joint"]


def test_motion_end_falls_back_to_last_planned_point(tmp_path: Path) -> None:
    ep = paper_like("pid_f", "pid", duration_s=1.5, motion_end_s=0.8)
    ep.motion_end_s = 0.8
    from tests.analysis.bagfactory import default_settings

    settings = default_settings(ep)
    del settings["planner"]["trajectory_duration_s"]
    ep.settings = settings
    rec = read_recording(write_bag(tmp_path, ep))
    assert rec.trajectory_duration_s == pytest.approx(0.8)


def test_unparseable_settings_are_noted_not_fatal(tmp_path: Path) -> None:
    ep = paper_like("pid_s", "pid", duration_s=0.3, motion_end_s=0.2)
    ep.raw_settings = "{not json"
    rec = read_recording(write_bag(tmp_path, ep))
    (note,) = rec.notes
    assert "settings is not valid JSON" in note and "armlab.episode" in note
    assert rec.controller == "pid" and rec.status == "ok"
    assert rec.trajectory_duration_s == pytest.approx(0.2)  # from the planned trajectory


def test_find_recordings_lists_bag_folders_and_bare_files_not_hidden_ones(tmp_path: Path) -> None:
    write_bag(tmp_path, paper_like("b_dir", "pid", duration_s=0.1))
    write_bag(tmp_path / "sub", paper_like("a_file", "pid", duration_s=0.1), as_directory=False)
    write_bag(tmp_path / ".tmp", paper_like("hidden", "pid", duration_s=0.1))
    found = find_recordings(tmp_path)
    assert found == [tmp_path / "b_dir", tmp_path / "sub" / "a_file.mcap"]


def test_msgdef_parser_reads_the_controller_state_schema() -> None:
    types = parse_msgdef(JTCS, msgdef(JTCS))
    names = [f.name for f in types[JTCS].fields]
    assert names[:6] == ["header", "joint_names", "reference", "feedback", "error", "output"]
    point = {f.name: f for f in types["trajectory_msgs/msg/JointTrajectoryPoint"].fields}
    assert point["positions"].base == "float64" and point["positions"].array == -1
    assert "builtin_interfaces/msg/Duration" in types


def test_msgdef_parser_skips_constants_and_reads_fixed_and_bounded_arrays() -> None:
    text = "uint8 MODE_A=1\nstring NAME = 'x'\nfloat64[3] xyz\nint32[<=4] some\nstring<=8 tag\n"
    parsed = parse_msgdef("pkg/msg/T", text)["pkg/msg/T"]
    assert [c.name for c in parsed.constants] == ["MODE_A", "NAME"]
    assert [(f.name, f.base, f.array) for f in parsed.fields] == [
        ("xyz", "float64", 3),
        ("some", "int32", -1),
        ("tag", "string", None),
    ]


def test_layout_rejects_a_message_cut_short() -> None:
    types = parse_msgdef("sensor_msgs/msg/JointState", msgdef("sensor_msgs/msg/JointState"))
    cdr = bytes([0, 1, 0, 0]) + (5).to_bytes(4, "little") + b"\x00" * 4
    with pytest.raises(ValueError):
        message_layout(types, "sensor_msgs/msg/JointState", cdr)


# --- damaged recordings --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kind", "words"),
    [
        ("truncated", "truncated"),
        ("bitflip", "corrupt"),
        ("empty", "empty file"),
        ("not_mcap", "not an MCAP file"),
    ],
)
def test_damaged_recording_gives_one_line_naming_file_and_problem(
    tmp_path: Path, kind: str, words: str
) -> None:
    path = write_bag(tmp_path, paper_like("bad", "pid", duration_s=0.5))
    damage(path, kind)
    with pytest.raises(RecordingError) as info:
        read_recording(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(mcap_file(path)) in message and words in message


@pytest.mark.parametrize("cut", [9, 100, -1, -9, -40])
def test_truncation_anywhere_is_detected(tmp_path: Path, cut: int) -> None:
    path = mcap_file(write_bag(tmp_path, paper_like("cut", "pid", duration_s=0.5)))
    data = path.read_bytes()
    path.write_bytes(data[:cut] if cut > 0 else data[: len(data) + cut])
    with pytest.raises(RecordingError, match="truncated"):
        read_recording(path)


def test_flipped_byte_in_uncompressed_chunk_fails_its_crc(tmp_path: Path) -> None:
    ep = paper_like("crc", "pid", duration_s=0.5)
    path = mcap_file(write_bag(tmp_path, ep, compression=CompressionType.NONE))
    off, n = first_chunk_records(path)
    flip_byte(path, off + n - 30)  # inside the last message's payload
    with pytest.raises(RecordingError, match="fails its CRC check"):
        read_recording(path)


def test_flipped_byte_outside_chunks_fails_the_data_section_crc(tmp_path: Path) -> None:
    ep = paper_like("dcrc", "pid", duration_s=0.5)
    path = mcap_file(write_bag(tmp_path, ep, mcap_options={"enable_data_crcs": True}))
    chunk_at, _, _ = first_chunk(path)
    # The chunk's message_start_time: covered by the data-section CRC only.
    flip_byte(path, chunk_at + 9 + 3)
    with pytest.raises(RecordingError, match="data section CRC"):
        read_recording(path)


@pytest.mark.parametrize("missing", ["/joint_states", "/controller_state"])
def test_recording_without_a_control_topic_is_rejected(tmp_path: Path, missing: str) -> None:
    topics = [t for t in ("/joint_states", "/controller_state", "/tf") if t != missing]
    path = write_bag(tmp_path, paper_like("nojs", "pid", duration_s=0.3), topics=topics)
    with pytest.raises(RecordingError, match=f"topic for .*default {missing}"):
        read_recording(path)


def test_bag_folder_without_mcap_is_rejected(tmp_path: Path) -> None:
    path = write_bag(tmp_path, paper_like("gone", "pid", duration_s=0.1))
    mcap_file(path).unlink()
    with pytest.raises(RecordingError, match=r"listed in metadata\.yaml but missing"):
        read_recording(path)


def test_samples_frame_is_tidy_one_row_per_sample_and_joint(tmp_path: Path) -> None:
    ep = paper_like("tidy", "pid", duration_s=0.2)
    rec = read_recording(write_bag(tmp_path, ep))
    counts = rec.samples.group_by("joint").len()
    assert set(counts.get_column("len").to_list()) == {len(ep.stamp_ns)}
    assert rec.samples.schema["time_s"] == pl.Float64
    assert rec.samples.get_column("episode").unique().to_list() == ["tidy"]


def test_flipped_byte_in_the_summary_fails_the_summary_crc(tmp_path: Path) -> None:
    path = mcap_file(write_bag(tmp_path, paper_like("scrc", "pid", duration_s=0.3)))
    footer_record = 1 + 8 + 8 + 8 + 4
    flip_byte(path, path.stat().st_size - 8 - footer_record - 1)  # last byte of the summary
    with pytest.raises(RecordingError, match="summary section CRC"):
        read_recording(path)
