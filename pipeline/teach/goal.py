""" "Use as goal": put the taught pose (or joints) into a params file as a scenario goal.

The file is edited round-trip (ruamel.yaml keeps its comments and layout), the
result is validated exactly as ``pipeline record`` validates it, and only then
written, atomically. A failed validation leaves the file untouched.
"""

from __future__ import annotations

import contextlib
import copy
import fcntl
import io
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal

from ruamel.yaml import YAML
from ruamel.yaml.comments import CommentedMap, CommentedSeq
from ruamel.yaml.error import YAMLError

from pipeline.errors import ParamsError, PipelineError
from pipeline.fsutil import atomic_write_bytes
from pipeline.kinematics.ik import pose_summary
from pipeline.params import Params, parse_params
from pipeline.robots.loaders import load_spec
from pipeline.robots.spec import RobotSpec
from pipeline.teach.session import TeachState
from pipeline.yamlio import parse_yaml

GoalKind = Literal["pose", "joints"]


def _flow(values: list[float]) -> CommentedSeq:
    seq = CommentedSeq(values)
    seq.fa.set_flow_style()
    return seq


def goal_from_state(state: TeachState, *, kind: GoalKind, solver: str) -> dict[str, Any]:
    """The scenario ``goal`` mapping for what the page shows.

    ``pose``: the flange target (position [m], quaternion w x y z) solved by
    ``solver`` at record time (nearest the scenario's start); ``joints``: the
    shown joints [rad] exactly.

    Raises:
        ParamsError: the shown target is unreachable (there is nothing to use).
    """
    if not state.reachable:
        raise ParamsError(f"the target is unreachable, nothing to use as goal: {state.reason}")
    if kind == "joints":
        return {"joints": [float(v) for v in state.q]}
    pose = pose_summary(state.target)
    return {
        "pose": {
            "position": pose["position"],
            "quaternion_wxyz": pose["quaternion_wxyz"],
            "solver": solver,
        }
    }


def write_goal(
    params_path: Path,
    *,
    scenario: str,
    robot: str,
    spec: RobotSpec,
    goal: dict[str, Any],
) -> Params:
    """Set ``scenarios.<scenario>.goal`` in ``params_path``; validate; write atomically.

    A new scenario gets ``robot`` and a start in the middle of every joint range.
    An existing one must be for the same robot.

    Returns:
        The validated params as written.

    Raises:
        ParamsError: missing or unreadable file, bad YAML, a scenario for another
            robot, or a result that does not validate (the file is left untouched).
    """
    if not scenario or not scenario.strip():
        raise ParamsError(f"{params_path}: scenario name must not be empty")
    if not params_path.is_file():
        raise ParamsError(f"{params_path}: no such params file (give an existing params YAML)")
    with _writers_lock(params_path):  # read, change and replace as one step per writer
        return _write_goal_locked(params_path, scenario=scenario, robot=robot, spec=spec, goal=goal)


@contextlib.contextmanager
def _writers_lock(params_path: Path) -> Iterator[None]:
    """An exclusive ``flock`` on the params file's folder: two teach servers (or two pages)
    writing one file take turns, so neither loses the other's change. (The folder, not the
    file: the file is replaced by a rename, which a lock on its old inode would not cover.)"""
    folder = params_path.absolute().parent
    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as err:
        raise ParamsError(f"{folder}: cannot lock the params file's folder ({err})") from err
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def _write_goal_locked(
    params_path: Path, *, scenario: str, robot: str, spec: RobotSpec, goal: dict[str, Any]
) -> Params:
    try:
        text = params_path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise ParamsError(f"{params_path}: cannot read params file ({err})") from err
    yaml = YAML()  # round-trip: comments and key order survive
    yaml.width = 100
    try:
        data = yaml.load(text)
    except YAMLError as err:
        raise ParamsError(f"{params_path}: not valid YAML ({err})") from err
    if not isinstance(data, dict):
        raise ParamsError(
            f"{params_path}: expected a mapping with scenarios, controllers, episodes"
        )
    scenarios = data.setdefault("scenarios", CommentedMap())
    if not isinstance(scenarios, dict):
        raise ParamsError(f"{params_path}: scenarios: expected a mapping")
    goal_node = CommentedMap()
    if "joints" in goal:
        goal_node["joints"] = _flow(goal["joints"])
    else:
        p = goal["pose"]
        goal_node["pose"] = CommentedMap(
            position=_flow(p["position"]),
            quaternion_wxyz=_flow(p["quaternion_wxyz"]),
            solver=p["solver"],
        )
    entry = scenarios.get(scenario)
    if entry is None:
        middle = [float(v) for v in 0.5 * (spec.lower + spec.upper)]
        scenarios[scenario] = CommentedMap(robot=robot, start=_flow(middle), goal=goal_node)
    else:
        if not isinstance(entry, dict):
            raise ParamsError(f"{params_path}: scenarios.{scenario}: expected a mapping")
        _same_robot(params_path, scenario, entry.get("robot"), spec)
        if _uses(data, entry) > 1:  # an anchor or alias (taught: *paper): change this one only
            entry = _unshared_copy(entry)
            scenarios[scenario] = entry
        entry["goal"] = goal_node
    out = io.StringIO()
    yaml.dump(data, out)
    new_text = out.getvalue()
    # validate what will be on disk, parsed the way `pipeline record` parses it
    parsed = parse_params(
        parse_yaml(new_text, source=str(params_path), error=ParamsError), source=str(params_path)
    )
    atomic_write_bytes(params_path, new_text.encode("utf-8"))
    return parsed


def _uses(node: object, target: object) -> int:
    """How many times ``target`` (by identity) appears in the tree under ``node``."""
    count, seen, stack = 0, set(), [node]
    while stack:
        item = stack.pop()
        if item is target:
            count += 1
        if id(item) in seen or not isinstance(item, dict | list):
            continue
        seen.add(id(item))
        stack.extend(item.values() if isinstance(item, dict) else item)
    return count


def _unshared_copy(entry: dict[Any, Any]) -> CommentedMap:
    """A deep copy of an anchored or aliased mapping with no anchors of its own (the
    original keeps its anchor for its other users)."""
    new = copy.deepcopy(entry)
    if not isinstance(new, CommentedMap):
        new = CommentedMap(new)
    stack: list[object] = [new]
    while stack:
        item = stack.pop()
        if isinstance(item, CommentedMap | CommentedSeq):
            if item.anchor.value is not None:
                item.anchor.value = None
                item.anchor.always_dump = False
            stack.extend(item.values() if isinstance(item, dict) else item)
    return new


def _same_robot(params_path: Path, scenario: str, robot: object, spec: RobotSpec) -> None:
    where = f"{params_path}: scenarios.{scenario}.robot"
    if not isinstance(robot, str):
        raise ParamsError(f"{where}: expected a robot name or path, got {robot!r}")
    try:
        other = load_spec(robot)
    except PipelineError as err:
        raise ParamsError(f"{where}: {err}") from err
    if other.name != spec.name or other.joints != spec.joints:
        raise ParamsError(
            f"{where}: is '{robot}' ({other.name}), not the taught robot '{spec.name}'; "
            "pick another scenario name"
        )


__all__ = ["GoalKind", "goal_from_state", "write_goal"]
