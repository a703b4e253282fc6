"""The setup section's armature and plant lines when controllers bring their own nominal
model or plant: each controller's, only when they differ (the same lines otherwise)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from pipeline.stages.report import run_report
from tests.analysis.bagfactory import default_settings, paper_like, write_bag

IDENTIFIED = [0.5, 0.5, 0.4, 0.1, 0.1, 0.1]


def setup_of(folder: Path, edits: dict[str, Callable[[dict[str, Any]], None]]) -> list[str]:
    """The ``### Setup`` lines of a report over one synthetic bag per ``controller-seed``
    of scenario ``s`` (seeds 0 and 1 each), its settings changed by ``edits[controller]``."""
    for controller, edit in edits.items():
        for seed in (0, 1):
            name = f"{controller}-{seed}"
            ep = paper_like(name, controller, duration_s=0.3, motion_end_s=0.2, scenario="s",
                            seed=seed)  # fmt: skip
            ep.settings = default_settings(ep)
            edit(ep.settings)
            write_bag(folder / "rec", ep)
    run_report(recordings_dir=folder / "rec", out_dir=folder / "out")
    lines = (folder / "out" / "report.md").read_text().splitlines()
    start = lines.index("### Setup")
    return lines[start : lines.index("Controllers:", start)]


def unchanged(settings: dict[str, Any]) -> None:
    pass


def own_nominal(settings: dict[str, Any]) -> None:
    """As the record stage writes a controller's own identified ``nominal:``."""
    settings["controller"]["nominal"] = {"file": "models/ur5-id.yaml", "sha256": "ab" * 32}
    settings["plant"]["nominal_armature"] = IDENTIFIED


def own_plant(settings: dict[str, Any]) -> None:
    """As the record stage writes a controller's own ``plant:`` (the scenario's plant is it)."""
    settings["controller"]["plant"] = settings["scenario"]["plant"] = {"payload_kg": 1.0}
    settings["plant"]["payload_kg"] = 1.0


def test_each_controller_own_nominal_gets_its_armature_and_plant_line(tmp_path: Path) -> None:
    lines = setup_of(tmp_path, {"pid": unchanged, "ctc": unchanged, "ctc_id": own_nominal})
    text = "\n".join(lines)
    head = "- Rotor armature of the nominal model [kg m²], per controller:"
    assert head in lines, text
    rows = lines[lines.index(head) + 1 : lines.index(head) + 3]
    assert rows[0].startswith("  - `pid`, `ctc`: [") and "`nominal: " not in rows[0], text
    assert rows[1].startswith(
        "  - `ctc_id`: [0.5, 0.5, 0.4, 0.1, 0.1, 0.1]; source: identified "
        "(`nominal: models/ur5-id.yaml`)"
    ), text
    plant = lines.index("- Plant, per controller (as in its first episode):")
    assert lines[plant + 1].startswith("  - `pid`, `ctc`: exact = ")
    assert lines[plant + 2].startswith("  - `ctc_id`: exact = ")
    assert "nominal_armature = [0.5, 0.5, 0.4, 0.1, 0.1, 0.1]" in lines[plant + 2]
    assert "- Plant: " not in text and "Rotor armature of the nominal model [kg m²]: " not in text


def test_each_controller_own_plant_gets_its_plant_line(tmp_path: Path) -> None:
    lines = setup_of(tmp_path, {"pid": unchanged, "pid_real": own_plant})
    plant = lines.index("- Plant, per controller (as in its first episode):")
    assert "payload_kg = 0" in lines[plant + 1] and lines[plant + 1].startswith("  - `pid`: ")
    assert "payload_kg = 1" in lines[plant + 2] and lines[plant + 2].startswith("  - `pid_real`: ")
    # one nominal model for all: one armature line, as before
    assert any(
        line.startswith("- Rotor armature of the nominal model [kg m²]: [") for line in lines
    )


def test_the_same_plant_and_model_for_all_keep_one_line_each(tmp_path: Path) -> None:
    """A controller's own plant that equals the scenario's, or no own ones at all: the
    lines read as they always did."""

    def same_plant(settings: dict[str, Any]) -> None:
        settings["controller"]["plant"] = dict(settings["scenario"]["plant"])

    for name, edits in (
        ("none", {"pid": unchanged, "ctc": unchanged}),
        ("same", {"pid": unchanged, "pid_same": same_plant}),
    ):
        lines = setup_of(tmp_path / name, edits)
        assert "per controller" not in "\n".join(lines), lines
        assert sum(line.startswith("- Plant: exact = ") for line in lines) == 1, lines
        assert sum(line.startswith("- Rotor armature of the nominal model") for line in lines) == 1
