"""Where ``package://NAME/...`` URIs resolve: the search path of robot description packages."""

from __future__ import annotations

from pathlib import Path


def package_search_path(extra: tuple[str, ...] = ()) -> tuple[Path, ...]:
    """Folders that ``package://NAME/...`` resolves in: ``extra`` (the option), then
    ``ARMLAB_PACKAGE_PATH`` and ``ROS_PACKAGE_PATH`` (``:``-separated), then the
    example-robot-data share folder when it is installed. ``NAME`` is a sub-folder of one of
    them (or the folder itself, when it is called ``NAME``)."""
    import os
    import sys

    folders = list(extra)
    for var in ("ARMLAB_PACKAGE_PATH", "ROS_PACKAGE_PATH"):
        folders += [f for f in os.environ.get(var, "").split(os.pathsep) if f]
    share = Path(sys.prefix) / "lib" / f"python{sys.version_info[0]}.{sys.version_info[1]}"
    share = share / "site-packages" / "cmeel.prefix" / "share"
    if (share / "example-robot-data").is_dir():
        folders.append(str(share))
    return tuple(Path(f).expanduser() for f in folders)
