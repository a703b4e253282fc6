"""The Ray executor's failures of Ray itself end in one line (no traceback)."""

from __future__ import annotations

import sys
import types
from pathlib import Path

import pytest

from pipeline.errors import PipelineError
from pipeline.stages.executors.ray import RayExecutor


def test_a_ray_start_up_timeout_is_one_line(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """Ray raises a bare Exception when a node times out during start-up (a loaded machine,
    a support process that died); it used to escape as a 40-line traceback."""
    fake = types.ModuleType("ray")
    calls: list[str] = []

    def init(**_: object) -> None:
        calls.append("init")
        raise Exception(  # what Ray 2.60 raises
            "The current node timed out during startup. This could happen because some of "
            "the raylet failed to startup or the GCS has become overloaded.\nmore"
        )

    fake.is_initialized = lambda: False  # type: ignore[attr-defined]
    fake.init = init  # type: ignore[attr-defined]
    fake.shutdown = lambda: calls.append("shutdown")  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "ray", fake)
    with pytest.raises(PipelineError) as err:
        RayExecutor().run([], {}, out_dir=tmp_path, force=False, commit="x", emit=lambda *a: None)
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("--executor ray: cannot start or join a local instance")
    assert "timed out during startup" in message
    # a local start is retried after a clean shutdown before it is given up
    assert calls == ["init", "shutdown"] * 3
    assert "after 3 attempts" in message
