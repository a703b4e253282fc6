"""Read a recording whole: every message of the chosen topics decoded at once, then paired
into the tidy frames of a :class:`~pipeline.log.recording.Recording`.

:func:`pipeline.log.reader.read_recording` sends recordings up to
:data:`pipeline.log.recording.STREAM_ABOVE_BYTES` here (longer ones to
:mod:`pipeline.log.windowed`, which builds the same frames from the same parts).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from pipeline.log.collect import Collector, pick_roles, planned_trajectory, scan_storage
from pipeline.log.labels import check_trajectory_duration, read_labels, reference_end_s
from pipeline.log.notes import (
    JS_OPTIONAL,
    dropped_note,
    missing_array_notes,
    no_pairs,
    read_notes,
    truth_note,
)
from pipeline.log.pairing import error_feedback, match_stamps, tidy, truth_at
from pipeline.log.recording import F64, ReadOptions, Recording, episode_name

__all__ = ["read_whole"]


def read_whole(
    source: Path, files: list[Path], options: ReadOptions, *, copies: Mapping[Path, Path]
) -> Recording:
    mcap_path = files[0]
    collector = Collector(options.topics)
    scanned = scan_storage(files, collector, salvage=options.salvage, copies=copies, source=source)
    roles = pick_roles(collector, scanned.present, mcap_path, scanned.salvaged)
    js_t, js_all = roles.js_group.concat()
    cs_t, cs_a = roles.cs_group.concat()
    js_cols = roles.js_cols
    js_a = js_all if js_cols is None else {k: v[:, js_cols] for k, v in js_all.items()}
    names = roles.names
    js_topic, cs_topic = roles.js_dec.topic, roles.cs_dec.topic
    rows_js, rows_cs = match_stamps(js_t, cs_t)
    if rows_js.size == 0:
        raise no_pairs(mcap_path)
    notes, lost_pct = read_notes(scanned, roles)
    notes += dropped_note(js_t.size - rows_js.size)
    notes += missing_array_notes(js_a, js_topic, JS_OPTIONAL)
    labels = read_labels(collector, source, options, roles.chosen, names)
    notes += labels.notes

    # Relative times: wall-clock header stamps (1.7e9 s) would otherwise swamp float64
    # resolution and put the motion end (a duration from the start) 50 years early.
    t0_ns = int(min(js_t[0], cs_t[0]))
    episode = episode_name(labels.metadata, source)
    cs_all = cs_a
    error, feedback = error_feedback(cs_all)
    truth = roles.truth
    truth_pos, truth_vel, rows_cs_gt = truth_at(
        cs_t, truth.concat() if truth else None, roles.gt_perm if truth else [], error
    )
    if truth is not None:
        notes += truth_note(cs_t.size - rows_cs_gt.size, cs_topic)
    planned = planned_trajectory(collector, roles.chosen["planned_trajectory"])
    contradicted = check_trajectory_duration(
        labels.settings,
        planned,
        end_s=(int(max(js_t[-1], cs_t[-1])) - t0_ns) * 1e-9,
        salvaged=scanned.damaged,
        control_period_s=float(np.median(np.diff(cs_t))) * 1e-9 if cs_t.size > 1 else 0.0,
        reference_end=reference_end_s(cs_t, cs_all["reference_position"], t0_ns),
        planned_topic=str(roles.chosen["planned_trajectory"]),
    )
    notes += [contradicted.note] if contradicted else []
    every_cs = rows_cs.size == cs_t.size and bool(np.all(rows_cs == np.arange(cs_t.size)))
    every_js = rows_js.size == js_t.size and bool(np.all(rows_js == np.arange(js_t.size)))

    def at_cs(a: F64) -> F64:
        return a if every_cs else a[rows_cs]

    def at_js(a: F64) -> F64:
        return a if every_js else a[rows_js]

    cs_rows = {k: at_cs(v) for k, v in cs_all.items()}
    samples = tidy(
        js_t if every_js else js_t[rows_js],
        {
            "position_rad": at_js(js_a["position"]),
            "velocity_rad_s": at_js(js_a["velocity"]),
            "effort_nm": at_js(js_a["effort"]),
            "reference_position_rad": cs_rows["reference_position"],
            "reference_velocity_rad_s": cs_rows["reference_velocity"],
            "error_rad": at_cs(error),
            "commanded_effort_nm": cs_rows["commanded_effort"],
            "true_position_rad": at_cs(truth_pos),
            "true_velocity_rad_s": at_cs(truth_vel),
        },
        names=names,
        t0_ns=t0_ns,
        episode=episode,
    )
    controller_states = tidy(
        cs_t,
        {
            "reference_position_rad": cs_all["reference_position"],
            "reference_velocity_rad_s": cs_all["reference_velocity"],
            "feedback_position_rad": feedback,
            "error_rad": error,
            "commanded_effort_nm": cs_all["commanded_effort"],
            "true_position_rad": truth_pos,
            "true_velocity_rad_s": truth_vel,
        },
        names=names,
        t0_ns=t0_ns,
        episode=episode,
    )
    return Recording(
        source=source,
        mcap_path=mcap_path,
        sha256=scanned.sha256,
        size_bytes=scanned.size,
        metadata=labels.metadata,
        settings=labels.settings,
        joint_names=names,
        samples=samples,
        controller_states=controller_states,
        planned=planned,
        robot_description=labels.urdf,
        topic_counts=dict(collector.topic_counts),
        decoded_messages=roles.js_group.count
        + roles.cs_group.count
        + (truth.count if truth else 0),
        notes=(*notes, *labels.settings_notes),
        has_ground_truth=truth is not None,
        salvaged=scanned.damaged,
        salvage_lost_pct=lost_pct,
        armlab_metadata=labels.ours,
        duration_contradicted=contradicted is not None,
        data_trajectory_duration_s=contradicted.duration_s if contradicted else None,
    )
