"""Duplicated messages in a recording are reported, not silently averaged in."""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.analysis.checks import duplicate_stamp_notes
from pipeline.log.reader import read_recording
from pipeline.stages.report import run_report
from tests.analysis.bagfactory import paper_like, write_bag


def _with_repeated_rows(name: str, rows: list[int]):
    ep = paper_like(name, "pid", duration_s=0.5, motion_end_s=0.3)
    idx = np.sort(np.concatenate([np.arange(ep.stamp_ns.size), rows]))
    arrays = {
        f.name: getattr(ep, f.name)[idx]
        for f in dataclasses.fields(ep)
        if isinstance(getattr(ep, f.name), np.ndarray)
    }
    return dataclasses.replace(ep, **arrays)


def test_a_clean_recording_has_no_duplicate_note(tmp_path):
    path = write_bag(tmp_path, paper_like("clean", "pid", duration_s=0.5, motion_end_s=0.3))
    assert duplicate_stamp_notes(read_recording(path)) == []


def test_messages_published_twice_are_named_with_their_count_and_first_stamp(tmp_path):
    path = write_bag(tmp_path, _with_repeated_rows("dup", [10, 10, 40]))
    notes = duplicate_stamp_notes(read_recording(path))
    stamp_s = paper_like("x", "pid", duration_s=0.5, motion_end_s=0.3).stamp_ns[10] * 1e-9
    assert notes, "a duplicated stamp must be noted"
    joint_states = [n for n in notes if n.startswith("/joint_states")]
    assert joint_states, notes
    # stamps 10 (three copies) and 40 (two copies): 2 stamps, 3 extra messages
    assert "2 stamp(s) occur more than once (3 duplicate message(s)" in joint_states[0]
    assert f"first at stamp {stamp_s:.6f} s" in joint_states[0]


def test_the_report_warns_about_duplicated_messages(tmp_path):
    rec = tmp_path / "rec"
    write_bag(rec, _with_repeated_rows("paper-pid", [5]))
    write_bag(rec, paper_like("paper-ctc", "ctc", duration_s=0.5, motion_end_s=0.3))
    result = run_report(recordings_dir=rec, out_dir=tmp_path / "rep")
    assert any(ep == "paper-pid" and "more than once" in note for ep, note in result.warnings)
    assert not any(ep == "paper-ctc" for ep, _ in result.warnings)


def test_duplicate_stamps_are_found_the_same_in_recorded_and_shuffled_row_order(tmp_path):
    # the recorded layout takes a hash-free check; any other order the group-by: same answer
    from pipeline.analysis.checks import duplicate_stamps

    clean = paper_like("clean", "pid", duration_s=0.5, motion_end_s=0.3)
    dup = _with_repeated_rows("dup", [10, 10, 40])
    for name, ep, rows in (("clean", clean, []), ("dup", dup, [10, 10, 40])):
        frame = read_recording(write_bag(tmp_path / name, ep)).samples
        shuffled = frame.sample(fraction=1.0, shuffle=True, seed=3)
        assert duplicate_stamps(frame) == duplicate_stamps(shuffled)
        assert (duplicate_stamps(frame) is None) == (not rows)
