"""Recordings the identification tests share: excitations run on the ideal UR5 plant."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from pipeline.control import make_controller
from pipeline.identify.fourier import FourierReference
from pipeline.log.bag import write_episode_bag
from pipeline.robots.loaders import load_spec
from pipeline.sim.runner import run_episode
from pipeline.trajectory import TrajectorySamples

MID_POSTURE = np.array([0.0, -1.2, 1.2, -1.0, 0.5, 0.0])


def fourier(seed: int, *, joints: slice = slice(None), periods: int = 1) -> FourierReference:
    """A fixed (not optimized) 5-harmonic, 0.1 Hz excitation; ``joints`` move, others rest."""
    rng = np.random.default_rng(seed)
    free = rng.normal(scale=0.06, size=(2, 6, 4))
    mask = np.zeros(6, dtype=bool)
    mask[joints] = True
    free[:, ~mask] = 0.0
    return FourierReference.from_free(
        MID_POSTURE, free.ravel(), harmonics=5, base_frequency_hz=0.1, periods=periods
    )


def record(path: Path, reference: FourierReference, *, hold_s: float = 0.5) -> Path:
    """Run ``reference`` under CTC on the ideal plant and write it as our recording."""
    spec = load_spec("ur5")
    result = run_episode(
        spec,
        reference=reference,
        controller=make_controller("ctc", spec),
        seed=0,
        hold_s=hold_s,
        preroll_s=0.2,
        # the unfiltered round trip's model is the plant's own semi-implicit Euler step
        physics_dt_s=0.001,
        integrator="Euler",
    )
    assert result.status == "ok", result.reason
    t = np.arange(0.0, reference.duration_s, 0.05)
    write_episode_bag(
        path,
        spec=spec,
        result=result,
        planned=TrajectorySamples(t, *reference.sample_many(t)),
        metadata={
            "episode": path.name,
            "scenario": "excitation",
            "controller": "ctc",
            "robot": "ur5",
            "seed": "0",
            "settings": json.dumps({"status": "ok"}),
        },
    )
    return path


@pytest.fixture(scope="session")
def ideal_bags(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two different 10 s excitations on the ideal plant: one to fit, one to validate."""
    root = tmp_path_factory.mktemp("ideal")
    return record(root / "fit", fourier(1)), record(root / "check", fourier(2))
