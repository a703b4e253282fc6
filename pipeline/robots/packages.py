"""Where ``package://NAME/...`` URIs resolve: the search path of robot description packages."""

from __future__ import annotations

from pathlib import Path


def package_search_path(extra: tuple[str, ...] = ()) -> tuple[Path, ...]:
    """Folders that ``package://NAME/...`` resolves in: ``extra`` (the option), then
    ``ARMLAB_PACKAGE_PATH`` and ``ROS_PACKAGE_PATH`` (``:``-separated), then the
    example-robot-data share folder when it is installed. ``NAME`` is a sub-folder of one of
    them (or the folder itself, when it is called ``NAME``)."""
    import os

    folders = [Path(f) for f in extra]
    for var in ("ARMLAB_PACKAGE_PATH", "ROS_PACKAGE_PATH"):
        folders += [Path(f) for f in os.environ.get(var, "").split(os.pathsep) if f]
    share = example_robot_data_share()
    if share is not None:
        folders.append(share)
    return tuple(f.expanduser() for f in folders)


def example_robot_data_share() -> Path | None:
    """The ``share`` folder holding ``example-robot-data/robots/``, found through the installed
    distribution (wherever pip put it: a venv, ``--user``, ``--target``), or None."""
    from importlib import metadata

    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        return None
    share = Path(str(dist.locate_file("cmeel.prefix/share")))
    return share if (share / "example-robot-data").is_dir() else None
