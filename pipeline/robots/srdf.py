"""SRDF (MoveIt's semantic description) on a loaded robot: disabled collision pairs and
named joint configurations (``group_state``, e.g. ``ready``)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from xml.etree import ElementTree

from pipeline.errors import SpecError
from pipeline.robots.spec import RobotSpec

__all__ = ["apply_srdf"]


def apply_srdf(spec: RobotSpec, path: Path, owner: Mapping[str, str]) -> RobotSpec:
    """``spec`` with the SRDF's disabled pairs (between the bodies the links merged into:
    ``owner`` maps every URDF link to its body) and its named states of the arm's joints.

    Raises:
        SpecError: unreadable SRDF, or one naming a link or joint the robot lacks.
    """
    source = str(path)
    try:
        root = ElementTree.fromstring(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise SpecError(f"{source}: cannot read SRDF ({err})") from err
    except ElementTree.ParseError as err:
        raise SpecError(f"{source}: not well-formed XML ({err})") from err
    pairs: set[tuple[str, str]] = set()
    for k, el in enumerate(root.iter("disable_collisions")):
        ends = []
        for attr in ("link1", "link2"):
            link = el.get(attr) or ""
            if link not in owner:
                raise SpecError(
                    f"{source}: disable_collisions[{k}].{attr}: unknown link {link!r} "
                    f"(not in {spec.source})"
                )
            ends.append(owner[link])
        a, b = sorted(ends)
        if a != b:
            pairs.add((a, b))
    states: list[tuple[str, tuple[float, ...]]] = []
    for el in root.iter("group_state"):
        values: dict[str, float] = {}
        for j in el.findall("joint"):
            try:
                values[j.get("name") or ""] = float(j.get("value") or "nan")
            except ValueError as err:
                raise SpecError(f"{source}: group_state {el.get('name')!r}: bad value") from err
            value = values[j.get("name") or ""]
            if not math.isfinite(value) and j.get("name") in spec.joint_names:
                raise SpecError(
                    f"{source}: group_state {el.get('name')!r}: joint {j.get('name')!r}: value "
                    f"{j.get('value')!r}, expected a finite number"
                )
        if all(name in values for name in spec.joint_names):
            states.append((el.get("name") or "", tuple(values[n] for n in spec.joint_names)))
    return dataclasses.replace(
        spec, disabled_pairs=tuple(sorted(pairs)), named_states=tuple(states)
    )
