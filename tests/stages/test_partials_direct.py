"""A campaign episode's metric partial, made in memory from its arrays (no bag written),
equals the one measured from its full bag, bit for bit; the partial file keeps it all,
and a damaged, foreign or old partial is refused in one line naming the file."""

from __future__ import annotations

import dataclasses
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import polars as pl
import pytest
import yaml

from pipeline.errors import ReportError
from pipeline.params import load_params
from pipeline.stages import campaign_run
from pipeline.stages.campaign_run import completion_marker, plan_run
from pipeline.stages.partials import (
    PARTIAL_DIR,
    SHARED_DIR,
    Partial,
    measure_bag,
    partial_path,
    read_partial,
)
from pipeline.stages.record import record

REPO = Path(__file__).parents[2]


def _params(tmp_path: Path) -> Path:
    data = yaml.safe_load((REPO / "params.yaml").read_text())
    for s in data["scenarios"].values():
        s.update(preroll_s=0.2, hold_s=0.2)
    data["campaigns"] = {
        "c": {
            "scenario": "paper-realistic",  # drawn plant, friction, sensor noise
            "controllers": ["pid", "ctc"],
            "seeds": 1,
            "keep_bags": {"every": 2},
        }
    }
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _same_frame(a: pl.DataFrame, b: pl.DataFrame, what: str) -> None:
    """Equal schemas and values, floats bit for bit (NaN payloads and -0.0 included)."""
    assert a.schema == b.schema, what
    assert a.height == b.height, what
    for name in a.columns:
        x, y = a.get_column(name), b.get_column(name)
        assert x.is_null().equals(y.is_null()), f"{what}.{name}: nulls"
        if x.dtype == pl.Float64:
            bits = [s.fill_null(0.0).to_numpy().view(np.uint64) for s in (x, y)]
            assert np.array_equal(*bits), f"{what}.{name}"
        else:
            assert x.equals(y), f"{what}.{name}"


def _same_value(a: Any, b: Any, what: str) -> None:
    if isinstance(a, pl.DataFrame):
        _same_frame(a, b, what)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape, what
        assert a.tobytes() == b.tobytes(), what
    elif dataclasses.is_dataclass(a) and not isinstance(a, type):
        assert type(a) is type(b), what
        for f in dataclasses.fields(a):
            _same_value(getattr(a, f.name), getattr(b, f.name), f"{what}.{f.name}")
    elif isinstance(a, tuple) and a and isinstance(a[0], np.ndarray):
        assert len(a) == len(b), what
        for k, (x, y) in enumerate(zip(a, b, strict=True)):
            _same_value(x, y, f"{what}[{k}]")
    elif isinstance(a, float):
        assert np.float64(a).tobytes() == np.float64(b).tobytes(), what
    else:
        assert a == b, what


def _same_partial(made: Partial, measured: Partial) -> None:
    """Everything equal but the bag's identity, which a bag never written has not."""
    assert made.recording.sha256 == "" and made.recording.size_bytes == 0
    assert len(measured.recording.sha256) == 64 and measured.recording.size_bytes > 0
    for f in dataclasses.fields(Partial):
        a, b = getattr(made, f.name), getattr(measured, f.name)
        if f.name in ("recording", "view"):
            rec_b = dataclasses.replace(measured.recording, sha256="", size_bytes=0)
            b = rec_b if f.name == "recording" else dataclasses.replace(b, recording=rec_b)
        if f.name == "row":
            assert a.get_column("sha256").to_list() == [""]
            b = b.with_columns(pl.lit("").alias("sha256"))
        if f.name == "task_space":
            assert a.keys() == b.keys()
            for k in a:
                assert a[k].tool == b[k].tool and a[k].spec.joint_names == b[k].spec.joint_names
                q = np.linspace(-1.0, 1.0, 6 * len(a[k].joint_names)).reshape(6, -1)
                assert np.array_equal(a[k].tcp_poses(q), b[k].tcp_poses(q))
            continue
        _same_value(a, b, f.name)


@pytest.mark.slow
def test_partial_made_in_memory_equals_the_one_from_its_bag(tmp_path, monkeypatch):
    params = load_params(_params(tmp_path))
    run = plan_run(params, "c", out=tmp_path)
    # every episode writes its bag too here, so its in-memory partial can be checked
    pending = [dataclasses.replace(e, drop_bag=False) for e in run.pending]
    assert [e.partial_code is not None for e in pending] == [True, True]
    made: dict[str, Partial] = {}
    original = campaign_run.keep_partial

    def keep(out_dir: Path, name: str, **kw: Any) -> None:
        assert kw.get("recording") is not None  # made in memory, not read from the bag
        from pipeline.stages.partials import measure_recording

        made[name] = measure_recording(kw["recording"], measure_code=kw["measure_code"])
        original(out_dir, name, **kw)

    monkeypatch.setattr(campaign_run, "keep_partial", keep)
    outcomes = record(
        params, pending, out_dir=run.out_dir, force=True, commit=run.commit,
        on_event=completion_marker(run, lambda *a: None),
    )  # fmt: skip
    assert [o.status for o in outcomes] == ["ok", "ok"]
    assert sorted(made) == sorted(e.name for e in pending)  # pid and ctc
    for name, partial in made.items():
        from_bag = measure_bag(run.out_dir / name, measure_code=run.measure_code)
        _same_partial(partial, from_bag)
        # the file keeps all of it (the bag's path follows the file's place)
        _same_partial(read_partial(partial_path(run.out_dir, name)), from_bag)
    # the campaign's repeated metadata is stored once, not per episode
    shared = list((run.out_dir / PARTIAL_DIR / SHARED_DIR).iterdir())
    sizes = [partial_path(run.out_dir, e.name).stat().st_size for e in pending]
    assert max(sizes) < 24_000, sizes
    assert len(shared) <= 9  # robot, scenario, loop, plan, planner, frames, URDF + 2 gains


@pytest.mark.slow
def test_a_dropped_bag_is_never_written_and_bad_partials_are_refused(tmp_path, monkeypatch):
    params = load_params(_params(tmp_path))
    run = plan_run(params, "c", out=tmp_path)
    kept, dropped = (e.name for e in run.pending)
    (run.out_dir / dropped).mkdir(parents=True)  # a stale bag of an earlier full run
    written: list[Path] = []
    from pipeline.log import bag

    original = bag.write_episode_bag

    def write(bag_dir: Path, **kw: Any) -> Any:
        written.append(bag_dir)
        return original(bag_dir, **kw)

    monkeypatch.setattr(bag, "write_episode_bag", write)
    record(
        params, run.pending, out_dir=run.out_dir, force=True, commit=run.commit,
        on_event=completion_marker(run, lambda *a: None),
    )  # fmt: skip
    assert [p.name for p in written] == [kept]
    assert not (run.out_dir / dropped).exists()
    assert plan_run(params, "c", out=tmp_path).pending == ()  # both done: resume skips
    path = partial_path(run.out_dir, dropped)
    assert read_partial(path).bag == dropped
    # each read has frames of its own (their empty schemas are built once per process)
    first = read_partial(path)
    first.recording.samples.insert_column(0, pl.Series("changed", [], dtype=pl.Int64))
    again = read_partial(path).recording.samples
    assert "changed" not in again.columns and again.height == 0
    good = path.read_bytes()
    for bad, why in (
        (good[: len(good) // 2], "unreadable metric partial"),
        (b"not arrow at all", "unreadable metric partial"),
    ):
        path.write_bytes(bad)
        with pytest.raises(ReportError, match=f"^{path}: {why}") as err:
            read_partial(path)
        assert "\n" not in str(err.value)
    path.write_bytes(good)
    # a foreign Arrow file
    other = path.with_name("other.arrow")
    pl.DataFrame({"x": [1]}).write_ipc_stream(other)
    with pytest.raises(ReportError, match=f"^{other}: unreadable metric partial"):
        read_partial(other)
    # a partial of the former format (a pickle) is refused, not unpickled
    old = path.with_suffix(".pkl")
    old.write_bytes(pickle.dumps({"format": 1}))
    with pytest.raises(ReportError, match=f"^{old}: metric partial format 1"):
        read_partial(old)
    # a shared part changed: refused, naming the partial and the part
    for part in (run.out_dir / PARTIAL_DIR / SHARED_DIR).glob("*.json"):
        part.write_bytes(part.read_bytes() + b" ")
    with pytest.raises(ReportError, match=f"^{path}: its shared part .* does not match"):
        read_partial(path)


@pytest.mark.slow
def test_a_dropped_episode_whose_measuring_fails_keeps_its_bag(tmp_path, monkeypatch):
    """Measuring in memory failing for any reason (here a ValueError) writes the bag the
    partial was to replace, so the report measures it from the file: nothing is lost."""
    params = load_params(_params(tmp_path))
    run = plan_run(params, "c", out=tmp_path)
    kept, dropped = (e.name for e in run.pending)

    def broken(*args: Any, **kwargs: Any) -> Any:
        raise ValueError("a bug in the measuring code")

    monkeypatch.setattr(campaign_run, "keep_partial", broken)
    record(params, run.pending, out_dir=run.out_dir, force=True, commit=run.commit)
    assert (run.out_dir / dropped).is_dir() and (run.out_dir / kept).is_dir()
    assert not partial_path(run.out_dir, dropped).exists()
