"""An episode's streams decoded in memory (the campaign path) equal the recording the
reader makes of the bag the writer makes of them, value for value, for each ROS distro
and a decimated /joint_states; and the value is checked once, whoever takes it."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from pipeline.errors import RecordingError
from pipeline.log.bag import write_streams
from pipeline.log.decode import Want
from pipeline.log.reader import read_recording
from pipeline.log.streams import EpisodeStreams
from pipeline.log.topics import PAIRED, ROLES, TOPICS, WANT, paired_columns, want_by_type
from pipeline.log.whole import episode_recording, reads_whole
from pipeline.robots import RobotSpec
from tests.log.test_writer import analytic_episode, episode_metadata
from tests.stages.test_partials_direct import _same_value


@pytest.mark.parametrize(("distro", "decimation"), [("jazzy", 1), ("humble", 3)])
def test_the_in_memory_recording_equals_the_bag_read_back(
    ur5: RobotSpec, tmp_path: Path, distro: str, decimation: int
) -> None:
    result, planned = analytic_episode(ur5, n_steps=400, t0_ns=1_700_000_000_123_456_789)
    streams = EpisodeStreams.of(
        spec=ur5,
        result=result,
        planned=planned,
        metadata=episode_metadata(),
        motion_start_ns=50_000_000,
        joint_state_decimation=decimation,
        tf_rate_hz=30.0,
        ros_distro=distro,
    )
    assert reads_whole(streams)
    bag_dir = tmp_path / "ctc_paper"
    summary = write_streams(bag_dir, streams)
    from_bag = read_recording(bag_dir)
    made = episode_recording(streams, bag_dir)
    assert made.sha256 == "" and made.size_bytes == 0
    assert dict(summary.message_counts) == made.topic_counts
    assert set(made.topic_counts) == {t.name for t in TOPICS}
    _same_value(made, dataclasses.replace(from_bag, sha256="", size_bytes=0), "recording")


def test_a_bad_value_is_refused_before_anything_is_filled(ur5: RobotSpec) -> None:
    result, planned = analytic_episode(ur5, n_steps=10)
    with pytest.raises(RecordingError, match=r"^tf_source: 'both', expected"):
        EpisodeStreams.of(
            spec=ur5,
            result=result,
            planned=planned,
            metadata=None,
            tf_source="both",  # type: ignore[arg-type]
        )
    with pytest.raises(RecordingError, match=r"^metadata: missing \['episode'"):
        EpisodeStreams.of(spec=ur5, result=result, planned=planned, metadata={})


def test_rows_of_one_message_type_decode_the_same_leaves() -> None:
    """The reader decodes a message type one way (:data:`WANT`, also for a role found by
    type): two rows of one type must not ask for different leaves."""
    for t in TOPICS:
        assert t.want is None or t.want == WANT[t.type], t.name
    for role, t in PAIRED.items():
        assert t.want is not None and set((t.paired or {}).values()) <= set(t.want.arrays), role


def test_a_second_topic_of_a_read_type_cannot_silently_decode_as_the_first() -> None:
    """A new row of a message type already read that wants other leaves is refused at
    import (naming both rows), not decoded with whichever row came last."""
    truth = ROLES["ground_truth"]
    assert truth.want is not None
    same = dataclasses.replace(truth, name="/other/joint_states", role="other")
    assert want_by_type((*TOPICS, same)) == WANT
    other = dataclasses.replace(same, want=Want(names=("name",), arrays={"effort": ("effort",)}))
    with pytest.raises(ValueError, match=r"/other/joint_states wants other leaves of "
                       r"sensor_msgs/msg/JointState than /joint_states"):  # fmt: skip
        want_by_type((*TOPICS, other))


def test_a_paired_column_is_added_once_from_an_array_its_row_decodes() -> None:
    truth = ROLES["ground_truth"]
    assert truth.paired is not None
    twice = dataclasses.replace(truth, name="/other/joint_states", role="other")
    with pytest.raises(ValueError, match=r"'true_position_rad', already paired by /ground_truth"):
        paired_columns((truth, twice))
    undecoded = dataclasses.replace(twice, paired={"other_effort_nm": "torque"})
    with pytest.raises(ValueError, match=r"pairs 'other_effort_nm' from 'torque', not an"):
        paired_columns((truth, undecoded))
    fine = dataclasses.replace(twice, paired={"other_effort_nm": "effort"})
    assert paired_columns((truth, fine)) == (*truth.paired, "other_effort_nm")
