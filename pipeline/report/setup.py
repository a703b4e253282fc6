"""The report's "Setup" section of a scenario or campaign: robot, start and goal, planner,
plant and each controller's gains as recorded."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from pipeline.analysis.findings import nominal_plant
from pipeline.contract import shown_fields
from pipeline.log.robot_facts import robot_facts
from pipeline.report import md
from pipeline.report.inputs import ReportData
from pipeline.robots.spec import RobotSpec
from pipeline.settings import LoopSettings, PlannerSettings, PlantSettings, plant_as_recorded


def _as_recorded(node: Any) -> dict[str, Any]:
    """A settings dataclass as its recording holds it: plain JSON data, keys sorted."""
    data: dict[str, Any] = json.loads(json.dumps(dataclasses.asdict(node), sort_keys=True))
    return plant_as_recorded(data, type(node)) if isinstance(node, PlantSettings) else data


def _given(node: Mapping[str, Any], key: str) -> Any:
    """A value of a mapping recorded as given (the scenario's params, the robot's YAML
    form); None when absent or empty."""
    value = node.get(key)
    return None if value == "" else value


def _fields_line(node: Any, cls: type, *, skip: Sequence[str] = ()) -> str:
    """``label = value`` for each field of a settings value that its declaration shows
    (:func:`pipeline.contract.shown_fields`), in declaration order, as recorded (a field
    declared ``added`` is not recorded at its default, and not shown then)."""
    if node is None:
        return md.NA
    recorded = _as_recorded(node)
    shown = [(k, label) for k, label in shown_fields(cls) if k not in skip and k in recorded]
    return "; ".join(f"{label} = {md.value(recorded[k])}" for k, label in shown) or md.NA


# Planner settings that the planner line states in words.
_PATH_KEYS = ("planner", "direct", "simplify", "n_waypoints", "n_states_before_simplify")


def _robot_source(robot: RobotSpec | None) -> str:
    """How the robot is given: its DH convention, or its description file and SHA-256."""
    if robot is not None and robot.dh_rows is None:
        return (
            f"from {md.value(robot.format)} `{md.value(robot.source)}` "
            f"(SHA-256 {robot.source_sha256[:12]}...)"
        )
    return f"DH convention {md.value(robot.convention if robot else None)}"


def _planner_line(planner: PlannerSettings | None) -> str:
    """What the planner did, in words, then its settings.

    ``direct`` = the straight joint-space segment start -> goal was collision-free, so it
    is the path: RRTConnect did not search and there was nothing to simplify.
    """
    if planner is None:
        return md.NA
    skip: tuple[str, ...] = ()
    head = None
    direct = planner.direct
    if direct is True:
        head = "direct joint-space segment start → goal (collision-free; RRTConnect not needed)"
        skip += _PATH_KEYS
    elif direct is False:
        name = md.value(planner.planner)
        n = md.value(planner.n_waypoints)
        if planner.simplify:
            raw = planner.n_states_before_simplify
            head = f"{name}, {n} waypoints after simplification (from {md.value(raw)} states)"
        else:
            head = f"{name}, {n} waypoints (not simplified)"
        skip += _PATH_KEYS
    rest = _fields_line(planner, PlannerSettings, skip=skip)
    if head is None:
        return rest
    return head if rest == md.NA else f"{head}; {rest}"


def _loop_lines(loop: LoopSettings | None) -> list[str]:
    """The loop between plant and controller, when it is not the ideal one (``loop:``)."""
    if loop is None or loop.ideal:
        return []
    return [f"- Loop (the same for every law): {_fields_line(loop, LoopSettings)}."]


def _armature_text(robot: RobotSpec, nominal: Sequence[float] | None, model: str | None) -> str:
    """The rotor armature the nominal model assumes (``nominal``: as the plant records
    it), and where its values come from (``model``: the identified ``nominal:`` model
    file, if any)."""
    shown = list(nominal) if nominal is not None else [float(a) for a in robot.armature]
    # a DH robot states its armature's source; a URDF/MJCF robot among its sidecar facts
    stated_by = robot.armature_source if robot.dh_rows is not None else ""
    source = stated_by or dict(robot.settings_sources).get("armature") or None
    stated = source if source is not None else "not stated in the robot file"
    if model is not None:  # the controllers' model is an identified one, not the file
        stated = f"identified (`nominal: {model}`); the robot file's: {stated}"
    return f"{md.value(shown)}; source: {stated}"


def _armature_lines(robot: RobotSpec | None, recs: Sequence[Any]) -> list[str]:
    """The rotor armature of the nominal model: the first episode's, or each controller's
    when one has a nominal model of its own (params ``controllers.NAME.nominal``) and
    theirs differ."""
    if robot is None:
        return []
    head = "- Rotor armature of the nominal model [kg m²]"

    def text(rec: Any) -> str:
        s = rec.settings
        own = s.controller.nominal
        model = own.file if own is not None else s.scenario.nominal
        return _armature_text(robot, s.plant.nominal_armature, model)

    if any(r.settings is not None and r.settings.controller.nominal for r in recs):
        each = _per_controller(recs, text)
        if len(each) > 1:
            return [f"{head}, per controller:", *each]
    return [f"{head}: {text(recs[0])}."]


def _per_controller(
    recs: Sequence[Any], text: Callable[[Any], str], *, say_if_varies: bool = True
) -> list[str]:
    """``  - `a`, `b`: <text>.`` per distinct ``text`` of each controller's first episode
    with settings, controllers in the order they first appear; one entry when every
    controller's is the same. ``say_if_varies``: name the episode shown when the
    controller's episodes differ (a nominal model per seed)."""
    firsts: dict[str, Any] = {}
    for rec in recs:
        if rec.settings is not None:
            firsts.setdefault(rec.controller, rec)
    shared: dict[str, list[str]] = {}
    for name, rec in firsts.items():
        shown = text(rec)
        mine = {text(r) for r in recs if r.controller == name and r.settings is not None}
        if say_if_varies and len(mine) > 1:
            shown += f" (in {rec.episode}; its other episodes differ)"
        shared.setdefault(shown, []).append(f"`{name}`")
    return [f"  - {', '.join(names)}: {shown}." for shown, names in shared.items()]


def _friction_lines(robot: RobotSpec | None) -> list[str]:
    """Where the plant's joint friction came from, for a robot that records its sources
    (a URDF or MJCF robot: scenario, sidecar, the file's own, or not stated)."""
    sources = dict(robot.settings_sources) if robot is not None else {}
    if "damping" not in sources:
        return []
    named = "; ".join(f"{k}: {sources[k]}" for k in ("damping", "frictionloss") if k in sources)
    return [f"- Where the plant's joint friction comes from: {named}."]


def _acceleration_lines(robot: RobotSpec | None) -> list[str]:
    """The acceleration limits the planner used and where they come from, for a robot that
    records its sources (a URDF or MJCF robot: its sidecar, or derived by the stated rule)."""
    sources = dict(robot.settings_sources) if robot is not None else {}
    if robot is None or "acceleration" not in sources:
        return []
    shown = md.value([float(f"{v:.3g}") for v in robot.acceleration_limits])
    return [f"- Acceleration limits [rad/s²]: {shown}; source: {sources['acceleration']}."]


def setup_section(data: ReportData, scenario: str) -> list[str]:
    """The ``### Setup`` section of a scenario (or campaign condition): its first
    episode's settings, and one row per episode (per controller and gains when many)."""
    recs = data.in_group(scenario)
    mixed = [m for m in data.mixed_settings if m.group == scenario]
    first = recs[0]
    s = first.settings
    planner = s.planner if s is not None else None

    def pose(key: str) -> str:
        # The planner records the joint-space start/goal it used.
        return md.value(_as_recorded(planner)[key] if planner is not None else None)

    robot = s.robot if s is not None else None
    # a bag without our settings: the robot its /robot_description describes, if any
    described = robot_facts(first).note if s is None else ""
    lines = [
        "### Setup",
        "",
        f"- Robot: **{first.robot}** ({len(first.joint_names)} joints: "
        f"{', '.join(first.joint_names)}), {described or _robot_source(robot)}.",
        f"- Start [rad]: {pose('start')}; goal [rad]: {pose('goal')}; "
        f"obstacles: {len(s.scenario.obstacles) if s is not None else 0}; "
        f"hold after the motion: {md.value(s.scenario.hold_s if s is not None else None)} s"
        + (f" (in {first.episode}; settings differ, below)." if mixed else "."),
        f"- Planner: {_planner_line(planner)}.",
        *_armature_lines(robot, recs),
        *_friction_lines(robot),
        *_acceleration_lines(robot),
        *_plant_line(data, recs),
        *_loop_lines(s.loop if s is not None else None),
        *(
            [
                f"- **Settings differ within this group** (these episodes are not one set-up; "
                f"the lines above are {first.episode}'s): "
                + "; ".join(m.note() for m in mixed)
                + "."
            ]
            if mixed
            else []
        ),
        "",
        "Controllers:",
        "",
    ]
    rows = []
    for rec in recs:
        gains = rec.settings.controller.gains if rec.settings is not None else None
        shown = md.value(dict(gains)) if gains is not None else md.NA
        rows.append([rec.episode, rec.controller, shown, rec.meta("seed"), rec.status])
    if len(rows) > md.MAX_EPISODE_COLUMNS:
        # one row per controller and gains: seeds and statuses summarised
        grouped: dict[tuple[str, str], list[list[str]]] = {}
        for row in rows:
            grouped.setdefault((row[1], row[2]), []).append(row)
        rows = [
            [
                f"{len(members)} episodes",
                ctrl,
                shown,
                md.seed_span([m[3] for m in members]),
                ", ".join(f"{k}: {v}" for k, v in md.count([m[4] for m in members]).items()),
            ]
            for (ctrl, shown), members in grouped.items()
        ]
    lines.append(md.table(["episode", "controller", "gains and settings", "seed", "status"], rows))
    return [
        *lines,
        *_nominal_lines(recs),
        *_plant_lines(recs),
        *_design_lines(recs),
        *_origin_lines(recs),
    ]


def _plant_text(plant: PlantSettings | None, exact: bool | None) -> str:
    """A plant's shown fields, then what ``exact`` (of its episodes) says of it."""
    return f"{_fields_line(plant, PlantSettings)}" + (
        "; link masses, centres of mass and inertias (and the armature above) drawn per "
        "episode seed, recorded in each bag's `settings.plant.links`."
        if exact is False
        else ": the controllers' nominal model **is** the plant, so model-based terms are "
        "exact by construction."
        if exact
        else "."
    )


def _plant_line(data: ReportData, recs: Sequence[Any]) -> list[str]:
    """The plant: the first episode's, or each controller's (its first episode's) when one
    has a plant or a nominal model of its own (params ``controllers.NAME.plant``,
    ``nominal``) and theirs differ."""
    first = recs[0].settings
    exact = nominal_plant(recs, data.protocol)
    line = f"- Plant: {_plant_text(first.plant if first is not None else None, exact)}"
    if not any(
        r.settings is not None and (r.settings.controller.plant or r.settings.controller.nominal)
        for r in recs
    ):
        return [line]

    def text(rec: Any) -> str:
        mine = [r for r in recs if r.controller == rec.controller]
        return _plant_text(rec.settings.plant, nominal_plant(mine, data.protocol))[:-1]

    # (a drawn plant differs by seed: the line says so)
    each = _per_controller(recs, text, say_if_varies=False)
    return (
        [line] if len(each) < 2 else ["- Plant, per controller (as in its first episode):", *each]
    )


def _distinct_texts(recs: Sequence[Any], text: Callable[[Any], str]) -> dict[str, list[str]]:
    """Per controller (in the order they first appear), the distinct ``text`` of its
    episodes' settings, in episode order; episodes without settings are skipped."""
    shown: dict[str, list[str]] = {}
    for rec in recs:
        if rec.settings is None:
            continue
        seen = shown.setdefault(rec.controller, [])
        if (line := text(rec.settings)) not in seen:
            seen.append(line)
    return shown


def _plant_lines(recs: Sequence[Any]) -> list[str]:
    """Which plant each controller ran on, when one has a plant of its own (params
    ``controllers.NAME.plant``): its plant as the bags record it, the others on their
    scenario's. No line when none has its own."""
    if not any(r.settings is not None and r.settings.controller.plant for r in recs):
        return []

    def text(s: Any) -> str:
        own = s.controller.plant
        plant = json.dumps(dict(own) if own else s.scenario.recorded()["plant"], sort_keys=True)
        whose = "its own" if own is not None else "the scenario's"
        return f"{whose} `plant: {plant}`"

    shown = _distinct_texts(recs, text)
    return [
        "",
        "Plant per controller (paired by seed: seed N draws each plant's own spread with N):",
        "",
    ] + [f"- {name}: {'; '.join(texts)}." for name, texts in shown.items()]


def _nominal_lines(recs: Sequence[Any]) -> list[str]:
    """Which nominal model each controller ran on, when one has a model of its own
    (params ``controllers.NAME.nominal``): the file and its SHA-256 as each bag records
    them, the others on their scenario's (the robot description's CAD values, or the
    scenario's ``nominal:``). No line when none has its own."""

    def text(s: Any) -> str:
        own = s.controller.nominal
        if own is not None:
            return f"`{own.file}` (SHA-256 {own.sha256[:16]}…)"
        if s.scenario.nominal is not None:
            return f"the scenario's `nominal: {s.scenario.nominal}`"
        return "the robot description's (CAD) values"

    shown = _distinct_texts(recs, text)
    if not any(r.settings is not None and r.settings.controller.nominal for r in recs):
        return []
    return ["", "Nominal model per controller (what its model-based terms and gains use):", ""] + [
        f"- {name}: {'; '.join(texts)}." for name, texts in shown.items()
    ]


def _origin_lines(recs: Sequence[Any]) -> list[str]:
    """Where each plug-in controller's code came from, as its bags record it (built-ins are
    this package's own code and get no line)."""
    seen: dict[str, str] = {}
    for rec in recs:
        ctrl = rec.settings.controller if rec.settings is not None else None
        origin = dict(ctrl.origin) if ctrl is not None else {}
        kind = origin.get("kind", "builtin")
        if kind == "builtin" or ctrl is None:
            continue
        if kind == "entry_point":
            text = (
                f"entry point `{origin.get('name', '?')} = {origin.get('value', '?')}` of "
                f"`{origin.get('group', '?')}`, distribution {origin.get('distribution', '?')} "
                f"{origin.get('version', '?')}"
            )
        else:
            text = (
                f"`{origin.get('object', ctrl.type)}` from {origin.get('path', '?')} "
                f"(SHA-256 {str(origin.get('sha256', '?'))[:16]}…)"
            )
        seen.setdefault(f"`{ctrl.type}`", text)
    if not seen:
        return []
    return ["", "Plug-in controllers (their code as recorded in each bag):", ""] + [
        f"- {name}: {text}." for name, text in seen.items()
    ]


_DESIGN_WORDS = {
    "path": "per joint the largest nominal inertia along the planned motion",
    "start": "the nominal inertia at the planned motion's start",
    "given": "the nominal inertia at a given configuration",
    "zero": "the nominal inertia at q = 0 (clipped into the joint limits; no planned motion)",
}


def _design_lines(recs: Sequence[Any]) -> list[str]:
    """Where each controller's default gains were designed (``gains.design_at``), one
    line per controller whose defaults depend on it (PID's do, CTC's do not)."""
    shown: dict[str, str] = {}
    for rec in recs:
        design = rec.settings.controller.design if rec.settings is not None else None
        if design is None or rec.controller in shown:
            continue
        where = _DESIGN_WORDS[design.at] + (
            f" {md.value(list(design.q_rad))} rad" if design.q_rad else ""
        )
        shown[rec.controller] = (
            f"- `{rec.controller}`'s default gains designed at **{design.at}** ({where}): "
            f"M_jj = {md.value(list(design.inertia_kg_m2))} kg m² "
            "(`gains.design_at`, docs/control.md)."
        )
    return ["", *shown.values()] if shown else []
