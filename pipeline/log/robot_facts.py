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

from pipeline.errors import SpecError
from pipeline.log.recording import Recording
from pipeline.model.urdf_xml import urdf_effort_limits
from pipeline.robots import RobotSpec, builtin_robot_names, load_spec

DESCRIPTION_SOURCE = "/robot_description"
"""The ``source`` of a robot built from a bag's ``/robot_description``."""

__all__ = ["RobotFacts", "robot_facts"]

FactsSource = Literal["settings", "builtin", "urdf"]


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
            ``builtin`` robot of the recorded name, or the bag's ``urdf``.
        note: for a robot from the bag's ``/robot_description``: which description and
            which frame the TCP is, or why the description gives no robot ("" otherwise).
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
    if spec is None:
        # a bag we did not write (or ours without its settings): the limits its
        # /robot_description (URDF) declares, never a built-in robot's of the same name
        for name, urdf_limit in urdf_effort_limits(rec.robot_description or "").items():
            if name in limits:
                limits[name] = urdf_limit
        described, note = described_robot(rec.robot_description or "")
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


@functools.lru_cache(maxsize=16)
def described_robot(urdf: str) -> tuple[RobotSpec | None, str]:
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
    tip = spec.joints[-1].link_name
    frame = "tool0" if "tool0" in links and tip != "tool0" else tip
    return spec, (
        f"robot from the bag's {DESCRIPTION_SOURCE} (URDF '{spec.name}', SHA-256 "
        f"{digest[:12]}...), TCP at frame '{frame}'"
    )
