"""The converted-mesh cache: content-addressed, atomic, never required."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.errors import SpecError
from pipeline.robots import mesh_glb as mg


@pytest.fixture
def box_dae(tmp_path: Path) -> Path:
    import trimesh

    box = trimesh.creation.box(extents=(0.1, 0.2, 0.3))
    box.visual.face_colors = (10, 138, 199, 255)
    path = tmp_path / "box.dae"
    box.export(path)
    return path


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("ARMLAB_CACHE_DIR", str(tmp_path / "cache"))
    mg.mesh_glb.cache_clear()
    yield tmp_path / "cache" / "mesh_glb"
    mg.mesh_glb.cache_clear()


def test_a_converted_mesh_is_stored_once_and_read_back_as_the_same_bytes(box_dae, cache):
    fresh = mg.convert_glb(str(box_dae))
    assert mg.mesh_glb(str(box_dae)) == fresh
    entries = list(cache.iterdir())
    assert len(entries) == 1 and entries[0].suffix == ".glb"  # no temporary file left
    assert entries[0].read_bytes() == fresh
    mg.mesh_glb.cache_clear()  # a new process: the disk entry is what it reads
    entries[0].write_bytes(b"from the cache")
    assert mg.mesh_glb(str(box_dae)) == b"from the cache"


def test_the_key_follows_the_file_content_and_the_scale(box_dae, cache):
    mg.mesh_glb(str(box_dae))
    mg.mesh_glb(str(box_dae), (2.0, 2.0, 2.0))
    import trimesh

    trimesh.creation.box(extents=(0.3, 0.2, 0.1)).export(box_dae)  # same path, new content
    mg.mesh_glb.cache_clear()
    assert mg.mesh_glb(str(box_dae)) == mg.convert_glb(str(box_dae))
    assert len(list(cache.glob("*.glb"))) == 3


def test_an_unwritable_cache_is_skipped(box_dae, tmp_path, monkeypatch):
    blocker = tmp_path / "not-a-dir"
    blocker.write_text("a file where the cache folder would be")
    monkeypatch.setenv("ARMLAB_CACHE_DIR", str(blocker))
    mg.mesh_glb.cache_clear()
    try:
        assert mg.mesh_glb(str(box_dae)) == mg.convert_glb(str(box_dae))
    finally:
        mg.mesh_glb.cache_clear()


def test_a_missing_mesh_file_is_one_spec_error(tmp_path, cache):
    with pytest.raises(SpecError, match=r"nothing\.dae: cannot read the mesh"):
        mg.mesh_glb(str(tmp_path / "nothing.dae"))
    assert not cache.exists() or not list(cache.iterdir())
