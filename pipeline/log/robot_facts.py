"""What a recording says about its robot, whichever kind of bag it is: the one adapter the
analysis and the report ask for a robot's name, joints, model and effort limits.

- **Ours** (``armlab_metadata``): the robot recorded by value in ``settings.robot``
  (:mod:`pipeline.robots.recorded`; never re-loaded from its file), else the built-in
  robot of the recorded name; effort limits from that spec.
- **Foreign** (a bag we did not write, or ours without its robot): the robot name its
  URDF declares (:mod:`pipeline.log.labels`), the joints of ``/joint_states`` and the
  effort limits its ``/robot_description`` URDF declares; never a built-in robot of the
  same name (a URDF that names its robot ``ur5`` is not our ur5). The robot itself (and so
  the TCP) is that URDF's, loaded as the URDF loader loads a file (the chain to its single
  leaf; the flange ``tool0`` where the URDF has one fixed to that leaf, else the leaf link),
  its visual and collision elements left out (kinematics and dynamics need no mesh);
  :attr:`RobotFacts.note` says which description and which frame, or why there is none.
- **Given** (``report --robot ROBOT`` for a foreign bag without ``/robot_description``): the
  robot ``ROBOT`` (a built-in name or a file: DH YAML, URDF, MJCF, sidecar), loaded as
  :func:`pipeline.robots.load_spec` loads it; its chain's joints must be the bag's (an
  error naming both otherwise); its effort limits and TCP, with a note as above.
- ``report --tip FRAME`` (a robot from a description or ``--robot``) puts the flange, so
  the TCP, at ``FRAME``: the last joint's link or a frame fixed to it (a sidecar's
  ``flange:`` does the same for a robot file).
"""

from __future__ import annotations

import functools
import hashlib
import re
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal
from xml.etree import ElementTree

from pipeline.errors import RecordingError, SpecError
from pipeline.log.recording import Recording
from pipeline.model.urdf_xml import urdf_effort_limits
from pipeline.robots import RobotSpec, builtin_robot_names, load_spec
from pipeline.robots.chain import FLANGE
from pipeline.robots.spec import IDENTITY

DESCRIPTION_SOURCE = "/robot_description"
"""The ``source`` of a robot built from a bag's ``/robot_description``."""

__all__ = ["RobotFacts", "robot_facts"]

FactsSource = Literal["settings", "builtin", "urdf", "given"]


@dataclass(frozen=True)
class RobotFacts:
    """A recording's robot as far as the recording tells.

    Attributes:
        name: the robot's name (our metadata or settings, a foreign bag's URDF; "n/a").
        joint_names: joint order, as in ``/joint_states``.
        spec: the robot spec (kinematics, inertials, limits); None when the recording
            does not give one (a foreign bag, or settings without a usable robot).
        effort_limits_nm: effort limit per joint [N m] (None where unknown).
        source: where ``spec`` and the limits come from: our recorded ``settings``, the
            ``builtin`` robot of the recorded name, the bag's ``urdf``, or the robot
            ``given`` as ``report --robot``.
        note: for a robot from the bag's ``/robot_description`` or ``--robot``: which
            description and which frame the TCP is, or why the description gives no robot
            ("" otherwise).
    """

    name: str
    joint_names: tuple[str, ...]
    spec: RobotSpec | None
    effort_limits_nm: Mapping[str, float | None]
    source: FactsSource
    note: str = ""


def robot_facts(rec: Recording) -> RobotFacts:
    """The robot facts of ``rec`` (see the module doc)."""
    limits: dict[str, float | None] = dict.fromkeys(rec.joint_names)
    spec = _spec(rec)
    if spec is None and rec.given_robot is not None and not rec.robot_description:
        given, note = given_robot(rec.given_robot, rec.given_tip, rec.joint_names)
        for j in given.joints:
            limits[j.name] = j.limits.effort
        return RobotFacts(given.name, rec.joint_names, given, limits, "given", note)
    if spec is None:
        # a bag we did not write (or ours without its settings): the limits its
        # /robot_description (URDF) declares, never a built-in robot's of the same name
        for name, urdf_limit in urdf_effort_limits(rec.robot_description or "").items():
            if name in limits:
                limits[name] = urdf_limit
        described, note = described_robot(rec.robot_description or "", rec.given_tip)
        if described is not None and described.joint_names != rec.joint_names:
            note += (
                f"; its chain's joints ({', '.join(described.joint_names)}) are not the "
                f"bag's ({', '.join(rec.joint_names)}): task space n/a"
            )
        return RobotFacts(rec.robot, rec.joint_names, described, limits, "urdf", note)
    for j in spec.joints:
        if j.name in limits:
            limits[j.name] = j.limits.effort
    source: FactsSource = "settings" if rec.settings is not None else "builtin"
    return RobotFacts(rec.robot, rec.joint_names, spec, limits, source)


def _spec(rec: Recording) -> RobotSpec | None:
    """The robot as recorded in settings.robot (by value); else the built-in robot of the
    recorded name; None for a bag without our metadata."""
    if not rec.armlab_metadata:
        return None
    if rec.settings is not None:
        return rec.settings.robot
    if rec.robot in builtin_robot_names():
        return load_spec(rec.robot)
    return None


def with_tip(spec: RobotSpec, tip: str | None, *, where: str) -> tuple[RobotSpec, str]:
    """``spec`` with its flange at frame ``tip`` (None: as it is), and that frame's name.

    Raises:
        SpecError: ``tip`` is neither the last joint's link nor a frame fixed to it
            (naming those that are).
    """
    last = spec.joints[-1].link_name
    on_last = {f.name: f for f in spec.frames if f.link == last}
    if tip is None or tip == FLANGE:
        named = FLANGE if spec.flange != IDENTITY or FLANGE in spec.description else last
        return spec, tip or named
    if tip == last:
        return replace(spec, flange=IDENTITY), tip
    if tip in on_last:
        return replace(spec, flange=on_last[tip].pose), tip
    choices = ", ".join([last, *sorted(on_last)])
    raise SpecError(
        f"--tip {tip}: not the last joint's link nor a frame fixed to it in {where} "
        f"(frames there: {choices})"
    )


@functools.lru_cache(maxsize=16)
def given_robot(robot: str, tip: str | None, joint_names: tuple[str, ...]) -> tuple[RobotSpec, str]:
    """The robot ``report --robot`` names for a bag without ``/robot_description``, its
    flange at ``tip``, and the note saying which robot and frame.

    Raises:
        SpecError: the robot does not load, or a bad ``tip``.
        RecordingError: its chain's joints are not the bag's ``joint_names``.
    """
    spec = load_spec(robot)
    if spec.joint_names != joint_names:
        raise RecordingError(
            f"--robot {robot}: its joints ({', '.join(spec.joint_names)}) are not the "
            f"bag's ({', '.join(joint_names)})"
        )
    spec, frame = with_tip(spec, tip, where=f"--robot {robot}")
    sha = f", SHA-256 {spec.source_sha256[:12]}..." if spec.source_sha256 else ""
    return spec, (
        f"robot from --robot {robot} ({spec.format} '{spec.name}'{sha}; the bag has no "
        f"{DESCRIPTION_SOURCE}), TCP at frame '{frame}'"
    )


@functools.lru_cache(maxsize=16)
def described_robot(urdf: str, tip: str | None = None) -> tuple[RobotSpec | None, str]:
    """The robot a bag's ``/robot_description`` URDF describes, and a note saying which
    description and which TCP frame (see the module doc); (None, why) when it describes
    none the loader accepts, (None, "") without a description."""
    if not urdf.strip():
        return None, ""
    digest = hashlib.sha256(urdf.encode("utf-8")).hexdigest()
    # kinematics and dynamics need no mesh: a foreign description's meshes are not here
    text = re.sub(r"<(visual|collision)\b.*?</\1\s*>|<(visual|collision)\b[^>]*/>", "", urdf,
                  flags=re.S)  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="armlab-description-") as folder:
        path = Path(folder) / "robot_description.urdf"
        path.write_text(text, encoding="utf-8")
        try:
            spec = load_spec(path)
        except SpecError as err:
            why = str(err).replace(str(path), DESCRIPTION_SOURCE)
            return None, f"no robot from the bag's {DESCRIPTION_SOURCE} ({why})"
    spec = replace(spec, source=DESCRIPTION_SOURCE, source_sha256=digest, loaded_from="",
                   description=urdf)  # fmt: skip
    try:
        links = {el.get("name") for el in ElementTree.fromstring(text).iter("link")}
    except ElementTree.ParseError:  # pragma: no cover - the loader parsed it
        links = set()
    last = spec.joints[-1].link_name
    frame = "tool0" if "tool0" in links and last != "tool0" else last
    if tip is not None:
        spec, frame = with_tip(spec, tip, where=f"the bag's {DESCRIPTION_SOURCE}")
    return spec, (
        f"robot from the bag's {DESCRIPTION_SOURCE} (URDF '{spec.name}', SHA-256 "
        f"{digest[:12]}...), TCP at frame '{frame}'"
    )
