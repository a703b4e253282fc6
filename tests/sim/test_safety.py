"""Execution safety: contacts and clearance along true joint states, against geometry
computed independently from the DH chain, and end to end on a low-gain PID."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.control import make_controller
from pipeline.errors import PipelineError, SimulationError
from pipeline.model.dh import link_frames
from pipeline.model.mjcf import FLOOR_Z_M, Box
from pipeline.robots.chain import chain
from pipeline.sim.references import PAPER_GOAL_RAD, PAPER_START_RAD, QuinticReference
from pipeline.sim.runner import run_episode
from pipeline.sim.safety import ExecutionSafety, assess_execution

STEP_NS = 1_000_000  # 1 kHz rows


def _stamps(n):
    return np.arange(n, dtype=np.int64) * STEP_NS


def _capsules_world(spec, q, link):
    """(start, end, radius) of each capsule of joint ``link``'s body, from DH FK alone."""
    frame = link_frames(spec, q)[link]
    out = []
    for seg in chain(spec)[link].segments:
        a = (frame @ np.append(seg.start, 1.0))[:3]
        b = (frame @ np.append(seg.end, 1.0))[:3]
        out.append((a, b, seg.radius))
    return out


def _segment_to_rectangle_2d(a, b, centre, half, samples=4001):
    """Distance in the xy plane from segment ab to an axis-aligned rectangle (dense)."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    pts = a[:2] + t * (b[:2] - a[:2])
    gap = np.maximum(np.abs(pts - centre[:2]) - half[:2], 0.0)
    return float(np.linalg.norm(gap, axis=1).min())


# --- a capsule through a box face, checked against plane geometry --------------------


DEPTH_M = 0.004


@pytest.fixture(scope="module")
def pan_through_box(ur5):
    """Shoulder pan sweeps the horizontal upper arm (a capsule of radius r at height h)
    over a box whose top face sits DEPTH_M above the capsule's underside."""
    ((a0, b0, r),) = _capsules_world(ur5, np.zeros(6), 1)
    assert a0[2] == pytest.approx(b0[2])  # horizontal at q = 0, and stays so under pan
    h = float(a0[2])
    top = h - r + DEPTH_M
    half = np.array([0.03, 0.03, 0.05])
    centre = np.array([-0.2 * np.cos(0.5), -0.2 * np.sin(0.5), top - half[2]])
    box = Box("box", tuple(centre.tolist()), tuple(half.tolist()))
    q = np.zeros((2001, 6))
    q[:, 0] = np.linspace(0.0, 1.0, len(q))
    # independently: at horizontal distance rho from the footprint, the round
    # underside of the capsule dips r - sqrt(rho^2 + (r - DEPTH)^2) into the box
    depth = np.empty(len(q))
    for k, qk in enumerate(q):
        ((a, b, _),) = _capsules_world(ur5, qk, 1)
        rho = _segment_to_rectangle_2d(a, b, centre, half)
        depth[k] = r - np.hypot(rho, r - DEPTH_M)
    return box, q, depth


def test_capsule_crossing_a_box_face_is_flagged_with_the_geometric_depth_and_times(
    ur5, pan_through_box
):
    box, q, depth = pan_through_box
    safety = assess_execution(ur5, q=q, stamp_ns=_stamps(len(q)), obstacles=[box])
    assert safety.touched
    (contact,) = safety.contacts
    assert contact.bodies == ("shoulder_lift_link", "box") and contact.kind == "obstacle"
    assert contact.max_depth_m == pytest.approx(DEPTH_M, abs=1e-6)
    inside = np.flatnonzero(depth > 0)
    assert abs(contact.first_ns - inside[0] * STEP_NS) <= STEP_NS
    assert abs(contact.last_ns - inside[-1] * STEP_NS) <= STEP_NS
    assert abs(contact.samples - len(inside)) <= 2
    assert inside[0] < contact.deepest_ns / STEP_NS < inside[-1]
    assert safety.min_clearance_m == pytest.approx(-DEPTH_M, abs=1e-6)
    assert safety.summary().startswith(f"touched box by 4.0 mm at t={inside[0] * 1e-3:.2f}")
    assert safety.summary().endswith(f"({contact.samples} samples): shoulder_lift_link–box")


def test_every_nth_row_checks_fewer_samples_and_keeps_the_last(ur5, pan_through_box):
    box, q, _ = pan_through_box
    full = assess_execution(ur5, q=q, stamp_ns=_stamps(len(q)), obstacles=[box])
    sparse = assess_execution(ur5, q=q, stamp_ns=_stamps(len(q)), obstacles=[box], every=7)
    assert sparse.samples_checked == len(range(0, len(q), 7)) + 1  # row 2000 added
    (c_full,), (c_sparse,) = full.contacts, sparse.contacts
    assert c_sparse.samples == pytest.approx(c_full.samples / 7, abs=2)
    assert c_full.first_ns <= c_sparse.first_ns < c_full.first_ns + 7 * STEP_NS


def test_obstacle_clearance_is_exact_where_mujocos_box_collider_misses_it(ur5):
    """20 mm between the elbow capsule's underside and a shelf: MuJoCo's capsule–box
    collider reports no contact within a 50 mm margin there; the clearance must."""
    ((a, b, r),) = _capsules_world(ur5, np.zeros(6), 2)
    underside = min(a[2], b[2]) - r
    shelf = Box("shelf", (-0.6, 0.0, underside - 0.02 - 0.05), (0.12, 0.1, 0.05))
    safety = assess_execution(ur5, q=np.zeros((1, 6)), stamp_ns=_stamps(1), obstacles=[shelf])
    assert not safety.touched
    obstacle = next(c for c in safety.clearances if c.kind == "obstacle")
    assert obstacle.bodies == ("elbow_link", "shelf")
    assert obstacle.distance_m == pytest.approx(0.02, abs=1e-9)


# --- free motion, floor --------------------------------------------------------------


def test_free_motion_reports_no_contact_and_a_positive_clearance(ur5):
    ref = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=3.0)
    q = ref.sample_many(np.arange(3000) * 1e-3)[0]
    safety = assess_execution(ur5, q=q, stamp_ns=_stamps(len(q)), obstacles=())
    assert not safety.touched and safety.contacts == ()
    assert 0.0 < safety.min_clearance_m <= safety.padding_m
    assert safety.summary().startswith("no contact")
    assert {c.kind for c in safety.clearances} <= {"self", "floor"}


def test_arm_lowered_into_the_floor_is_flagged_with_the_plane_depth(ur5):
    """Shoulder lift turns the stretched arm down through the floor; the elbow link's
    depth below the plane follows from its capsule's lowest endpoint (DH FK)."""
    q = np.zeros((1201, 6))
    q[:, 1] = np.linspace(0.0, 1.2, len(q))
    safety = assess_execution(ur5, q=q, stamp_ns=_stamps(len(q)), obstacles=())
    by_pair = {c.bodies: c for c in safety.contacts}
    elbow = by_pair[("elbow_link", "ground")]
    assert elbow.kind == "floor"
    depth = np.array(
        [
            max(FLOOR_Z_M - (min(a[2], b[2]) - r) for a, b, r in _capsules_world(ur5, qk, 2))
            for qk in q
        ]
    )
    assert elbow.max_depth_m == pytest.approx(depth.max(), abs=1e-9)
    inside = np.flatnonzero(depth > 0)
    assert abs(elbow.first_ns - inside[0] * STEP_NS) <= STEP_NS
    assert elbow.last_ns == (len(q) - 1) * STEP_NS
    assert all(c.kind == "floor" for c in safety.contacts)
    assert "touched ground by" in safety.summary()


# --- end to end ------------------------------------------------------------------------


def test_low_gain_pid_sagging_onto_a_shelf_is_flagged_end_to_end(ur5):
    """A shelf 20 mm under the elbow at the start pose. A PID tuned to 10 rad/s lets
    gravity pull the arm down (kp ~ m w^2 is 16x softer than the default's) and the
    plant lands on the shelf; the default 40 rad/s PID stays clear of it."""
    ((a, b, r),) = _capsules_world(ur5, np.zeros(6), 2)
    shelf = Box("shelf", (-0.6, 0.0, min(a[2], b[2]) - r - 0.02 - 0.05), (0.12, 0.1, 0.05))
    reference = QuinticReference.between(PAPER_START_RAD, PAPER_GOAL_RAD, duration_s=2.0)
    results = {}
    for omega in (10.0, 40.0):
        result = run_episode(
            ur5,
            reference=reference,
            controller=make_controller("pid", ur5, {"omega_n_rad_s": omega}),
            seed=0,
            obstacles=[shelf],
            hold_s=1.0,
        )
        assert result.ok, result.reason
        results[omega] = assess_execution(
            ur5, q=result.q_true, stamp_ns=result.stamp_ns, obstacles=[shelf]
        )
    soft = results[10.0]
    assert soft.touched
    elbow = next(c for c in soft.contacts if c.bodies == ("elbow_link", "shelf"))
    assert elbow.kind == "obstacle"
    assert 1e-4 < elbow.max_depth_m < 0.02  # soft contact: mm, not the 20 mm sag
    assert elbow.first_ns < 0.5e9 and elbow.samples > 100
    stiff = results[40.0]
    assert not stiff.touched
    obstacle = next(c for c in stiff.clearances if c.kind == "obstacle")
    assert 0.0 < obstacle.distance_m < 0.02 + 1e-9


# --- contract, errors ------------------------------------------------------------------


def test_to_dict_is_json_and_round_trips(ur5, pan_through_box):
    box, q, _ = pan_through_box
    safety = assess_execution(ur5, q=q, stamp_ns=_stamps(len(q)), obstacles=[box])
    data = json.loads(json.dumps(safety.to_dict()))
    assert data["touched"] is True and data["summary"] == safety.summary()
    assert data["min_clearance_m"] == safety.min_clearance_m
    assert ExecutionSafety.from_dict(data) == safety


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"q": np.zeros((3, 5))}, r"^q: expected \(N, 6\) joint positions of ur5, got shape"),
        ({"stamp_ns": np.zeros(3)}, r"^stamp_ns: expected 3 integer stamps"),
        ({"stamp_ns": _stamps(4)}, r"^stamp_ns: expected 3 integer stamps"),
        ({"q": np.full((3, 6), np.nan)}, r"^q: row 0 is not finite"),
        ({"padding_m": -0.1}, r"^padding_m: expected a finite distance >= 0"),
        ({"every": 0}, r"^every: expected an integer >= 1"),
    ],
)
def test_bad_inputs_are_refused_in_one_line(ur5, kwargs, match):
    args = {"q": np.zeros((3, 6)), "stamp_ns": _stamps(3), "obstacles": (), **kwargs}
    with pytest.raises(SimulationError, match=match) as err:
        assess_execution(ur5, **args)
    assert isinstance(err.value, PipelineError) and "\n" not in str(err.value)


# --- skipping provably clear rows ----------------------------------------------------


def _held(q, rows=1500):
    """``q`` with its first and last rows held for ``rows`` more rows each (settled phases)."""
    return np.concatenate([np.repeat(q[:1], rows, axis=0), q, np.repeat(q[-1:], rows, axis=0)])


def test_skipping_within_a_bound_keeps_contacts_exact_and_checks_few_settled_rows(
    ur5, pan_through_box
):
    box, q, _ = pan_through_box
    q = _held(q)
    stamps = _stamps(len(q))
    full = assess_execution(ur5, q=q, stamp_ns=stamps, obstacles=[box])
    skip = assess_execution(ur5, q=q, stamp_ns=stamps, obstacles=[box], skip_within_m=5e-4)
    assert full.samples_checked == len(q)
    assert skip.skip_within_m == 5e-4 and full.skip_within_m == 0.0
    # the held phases cost a few checks; the sweep is checked about row by row
    assert skip.samples_checked < len(q) - 2 * 1400
    assert skip.contacts == full.contacts  # spans, sample counts, depths: identical
    for a, b in zip(skip.clearances, full.clearances, strict=True):
        assert (a.kind, a.bodies) == (b.kind, b.bodies)
        assert b.distance_m <= a.distance_m <= b.distance_m + 5e-4


def test_a_two_row_dip_into_the_floor_between_settled_phases_is_caught(ur5):
    """Rows far from anything are skipped, yet a contact two rows long is found: the
    skip bound is distance-based, not a fixed stride."""
    q = np.zeros((4001, 6))
    q[2000:2002, 1] = 1.2  # the stretched arm swung into the floor for two rows
    stamps = _stamps(len(q))
    skip = assess_execution(ur5, q=q, stamp_ns=stamps, obstacles=(), skip_within_m=1e-3)
    full = assess_execution(ur5, q=q, stamp_ns=stamps, obstacles=())
    assert skip.samples_checked < 20
    assert skip.touched and skip.contacts == full.contacts
    assert {c.first_ns for c in skip.contacts} == {2000 * STEP_NS}
    assert all(c.samples == 2 for c in skip.contacts)
    # a stride of 7 rows (``every``) misses it
    assert not assess_execution(ur5, q=q, stamp_ns=stamps, obstacles=(), every=7).touched


def test_skip_bound_must_be_a_distance(ur5):
    with pytest.raises(SimulationError, match=r"^skip_within_m: expected a finite distance"):
        assess_execution(
            ur5, q=np.zeros((3, 6)), stamp_ns=_stamps(3), obstacles=(), skip_within_m=-1.0
        )
