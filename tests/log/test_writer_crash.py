"""A writer killed with SIGKILL never leaves a partial bag under a final name.

The writer runs in a subprocess; hooks make it stop at a chosen point (inside the MCAP data,
or with the directory complete but not yet renamed) so the kill lands mid-write every time,
and one run is killed at whatever moment it has reached after it started writing.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from pipeline.constants import TOPIC_CONTROLLER_STATE

WRITER = textwrap.dedent(
    """
    import json, sys, time
    from pathlib import Path
    import numpy as np
    from pipeline.log import bag, mcap, rosbag2
    from pipeline.robots import load_spec
    from pipeline.sim.result import EpisodeResult, TrajectorySamples

    mode, target, n_steps, force = sys.argv[1], Path(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
    spec = load_spec("ur5")
    st = np.arange(n_steps, dtype=np.int64) * 1_000_000
    q = np.sin(np.outer(st * 1e-9, np.arange(1, 7)))
    result = EpisodeResult(spec.joint_names, st, q, q, q, q, q, q, q, q, q, q > 2)
    times = np.linspace(0.0, 1.0, 11)
    planned = TrajectorySamples(times, np.zeros((11, 6)), np.zeros((11, 6)), np.zeros((11, 6)))
    meta = {k: "x" for k in bag.REQUIRED_METADATA_KEYS} | {"settings": "{}", "controller": mode}

    def hang(*args, **kwargs):
        print("ready", flush=True)
        time.sleep(120)

    if mode == "mid_mcap":  # stop while compressing the third chunk
        real = mcap.zstandard.ZstdCompressor

        class Stalling:
            def __init__(self, **kwargs):
                self.inner, self.calls = real(**kwargs), 0

            def compress(self, data):
                self.calls += 1
                if self.calls == 3:
                    hang()
                return self.inner.compress(data)

        mcap.zstandard = type("zstd", (), {"ZstdCompressor": Stalling})
    elif mode == "before_publish":  # everything written and fsynced, not yet renamed
        rosbag2._publish = hang
    else:
        print("ready", flush=True)
    bag.write_episode_bag(target, spec=spec, result=result, planned=planned, metadata=meta,
                          force=force == "force")
    print("done", flush=True)
    """
)


def start_writer(mode: str, target: Path, n_steps: int, *, force: bool) -> subprocess.Popen[str]:
    args = [mode, str(target), str(n_steps), "force" if force else "no"]
    return subprocess.Popen(
        [sys.executable, "-c", WRITER, *args],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).parents[2])},
    )


def kill(proc: subprocess.Popen[str]) -> None:
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL


def snapshot(bag_dir: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(bag_dir.iterdir())}


def controller(bag_dir: Path) -> str:
    with open(bag_dir / f"{bag_dir.name}_0.mcap", "rb") as f:
        [record] = make_reader(f).iter_metadata()
    return record.metadata["controller"]


@pytest.fixture(scope="module")
def earlier(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A finished recording next to which the killed writers work."""
    root = tmp_path_factory.mktemp("recordings")
    proc = start_writer("plain", root / "earlier", 500, force=False)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 0 and out.split() == ["ready", "done"]
    return root / "earlier"


@pytest.mark.parametrize("mode", ["mid_mcap", "before_publish"])
def test_killed_writer_leaves_no_partial_bag_and_earlier_bag_intact(
    earlier: Path, mode: str
) -> None:
    root = earlier.parent
    before = snapshot(earlier)
    target = root / f"new_{mode}"
    proc = start_writer(mode, target, 3000, force=False)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    partial = root / f".{target.name}.partial-{proc.pid}"
    assert partial.is_dir()  # it was really writing
    kill(proc)

    assert not os.path.lexists(target)
    assert snapshot(earlier) == before
    # The next write of that name succeeds and removes the dead writer's partial directory.
    proc = start_writer("plain", target, 200, force=False)
    proc.communicate(timeout=120)
    assert proc.returncode == 0 and controller(target) == "plain"
    assert not partial.exists()


def test_killed_forced_overwrite_keeps_the_old_recording(earlier: Path) -> None:
    before = snapshot(earlier)
    proc = start_writer("before_publish", earlier, 300, force=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    kill(proc)
    assert snapshot(earlier) == before
    assert controller(earlier) == "plain"


def test_writer_killed_at_any_moment_leaves_a_complete_bag_or_none(earlier: Path) -> None:
    root = earlier.parent
    before = snapshot(earlier)
    target = root / "big"
    proc = start_writer("plain", target, 120_000, force=False)  # 2 min at 1 kHz
    assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
    partial = root / f".big.partial-{proc.pid}"
    while not (partial / "big_0.mcap").exists() and proc.poll() is None:
        time.sleep(0.001)
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)  # it may finish just before: both outcomes are valid
    proc.wait(timeout=30)
    if os.path.lexists(target):  # finished before the kill landed: must be whole
        with open(target / "big_0.mcap", "rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None
        counts = {c.topic: summary.statistics.channel_message_counts[i]
                  for i, c in summary.channels.items()}  # fmt: skip
        assert counts[TOPIC_CONTROLLER_STATE] == 120_000
    assert snapshot(earlier) == before
