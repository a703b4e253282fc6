"""Campaign resume marks vouch for the bag's bytes; a mark of the wrong file type is one line."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest
import yaml

from pipeline.params import load_params
from pipeline.stages.campaign_run import DONE_DIR, MCAP_MAGIC, MarkError, mark_done, plan_run

REPO = Path(__file__).parents[2]


@pytest.fixture
def campaign(tmp_path: Path) -> tuple[Path, Path]:
    """A two-episode campaign whose episodes are 'recorded' (whole bags, marked)."""
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    data["campaigns"] = {"c": {"scenario": "paper-realistic", "controllers": ["pid", "ctc"]}}
    params = tmp_path / "params.yaml"
    params.write_text(yaml.safe_dump(data))
    out = tmp_path / "out"
    run = plan_run(load_params(params), "c", out=out)
    for k, e in enumerate(run.pending):
        bag = run.out_dir / e.name
        bag.mkdir(parents=True)
        (bag / "metadata.yaml").write_text(f"episode: {e.name}\n")
        (bag / f"{e.name}_0.mcap").write_bytes(MCAP_MAGIC + bytes([k]) * 64 + MCAP_MAGIC)
        from pipeline.stages.campaign_expand import episode_fingerprint

        mark_done(run.out_dir, e.name, episode_fingerprint(e, commit=run.commit))
    return params, run.out_dir


def _plan(params: Path, out_dir: Path):  # type: ignore[no-untyped-def]
    return plan_run(load_params(params), "c", out=out_dir.parent)


def test_marked_whole_bags_are_skipped(campaign):
    run = _plan(*campaign)
    assert len(run.skipped) == 2 and not run.pending and not run.changed


def test_a_bit_flipped_bag_is_recorded_again_and_named(campaign):
    params, out_dir = campaign
    mcap = next(out_dir.glob("*/*.mcap"))
    data = bytearray(mcap.read_bytes())
    data[20] ^= 1
    mcap.write_bytes(bytes(data))
    run = _plan(params, out_dir)
    assert [e.name for e in run.pending] == [mcap.parent.name]
    assert run.changed == (mcap.parent.name,)


def test_a_bag_swapped_for_another_episodes_is_recorded_again(campaign):
    params, out_dir = campaign
    a, b = sorted(p for p in out_dir.iterdir() if not p.name.startswith("."))
    a.rename(out_dir / "tmp")
    b.rename(a)
    (out_dir / "tmp").rename(b)
    run = _plan(params, out_dir)
    assert sorted(run.changed) == sorted([a.name, b.name]) and not run.skipped


def test_done_that_is_a_file_is_one_line(campaign):
    params, out_dir = campaign
    for mark in (out_dir / DONE_DIR).iterdir():
        mark.unlink()
    (out_dir / DONE_DIR).rmdir()
    (out_dir / DONE_DIR).write_text("x")
    with pytest.raises(MarkError, match=r"\.done: the campaign's marks folder is a file"):
        _plan(params, out_dir)


def test_a_mark_that_is_a_directory_is_one_line(campaign):
    params, out_dir = campaign
    mark = next((out_dir / DONE_DIR).iterdir())
    mark.unlink()
    mark.mkdir()
    with pytest.raises(MarkError, match="completion mark is a directory"):
        _plan(params, out_dir)


def test_a_mark_that_is_a_fifo_is_refused_without_blocking(campaign):
    params, out_dir = campaign
    mark = next((out_dir / DONE_DIR).iterdir())
    mark.unlink()
    os.mkfifo(mark)
    caught: list[BaseException] = []

    def plan() -> None:
        try:
            _plan(params, out_dir)
        except BaseException as err:  # handed to the test thread
            caught.append(err)

    t = threading.Thread(target=plan, daemon=True)
    t.start()
    t.join(timeout=30)
    if t.is_alive():  # unblock the reader so the thread ends, then fail
        with open(mark, "wb"):
            pass
        pytest.fail("reading a FIFO mark blocked")
    assert len(caught) == 1 and isinstance(caught[0], MarkError), caught
    assert "completion mark" in str(caught[0]) and "FIFO" in str(caught[0])
