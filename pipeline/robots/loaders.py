"""Loading a robot: by built-in name or by path, through one loader per file format.

:data:`LOADERS` maps a file suffix to its loader; adding a format is one loader file and
one entry there (and, for a format with link meshes or primitives, one in
:data:`GEOMETRY`). Loaded robots are cached per process (per file content for paths).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from importlib import resources
from pathlib import Path

from pipeline.errors import SpecError, unknown_name_message
from pipeline.robots.dh_yaml import parse_dh_text
from pipeline.robots.facts import with_derived_accelerations
from pipeline.robots.spec import NAME_RULE, RobotSpec, check_name

BUILTIN_SIDECAR = ".armlab.yaml"


def builtin_robot_names() -> list[str]:
    """Names of the robots shipped inside the package."""
    folder = resources.files("pipeline.robots")
    return sorted(
        p.name.removesuffix(BUILTIN_SIDECAR).removesuffix(".yaml")
        for p in folder.iterdir()
        if p.name.endswith(".yaml")
    )


LOADERS: dict[str, str] = {
    ".yaml": "pipeline.robots.dh_yaml:load_dh_yaml",
    ".yml": "pipeline.robots.dh_yaml:load_dh_yaml",
    ".urdf": "pipeline.robots.urdf_loader:load_urdf",
    ".urdf.xml": "pipeline.robots.urdf_loader:load_urdf",
    ".xml": "pipeline.robots.mjcf_loader:load_mjcf",
    ".armlab.yaml": "pipeline.robots.urdf_loader:load_sidecar",
}
"""Robot file loaders by suffix, ``module:function`` taking ``(path, *, package_path)`` and
returning a :class:`RobotSpec`: a new format is one loader file and one entry here."""

GEOMETRY: dict[str, str] = {
    "urdf": "pipeline.robots.link_geometry:URDF_GEOMETRY",
}
"""Link geometry by :attr:`RobotSpec.format`, ``module:name`` of a
:class:`pipeline.robots.link_geometry.FormatGeometry`: the links' visual and collision
geometry the viewers draw and the link graph the collision matrix walks. A format that
describes meshes or primitives adds its entry here (its FormatGeometry beside its
loader); one without (DH YAML, MJCF) is drawn as capsules."""


def loader_suffix(path: Path) -> str | None:
    """The :data:`LOADERS` key of a file name (the longest suffix that matches), or None."""
    name = path.name.lower()
    found = [s for s in LOADERS if name.endswith(s)]
    return max(found, key=len) if found else None


def load_spec(name_or_path: str | Path, *, package_path: tuple[str, ...] = ()) -> RobotSpec:
    """Load a robot by built-in name (``"ur5"``) or by path to a robot file (DH YAML, URDF, MJCF:
    see :data:`LOADERS`).

    Built-in robots are parsed once per process (they are package data); a file once per
    process and content.

    Raises:
        SpecError: unknown name (lists the available ones), unreadable file or
            invalid content (names the file and field path).
    """
    text = str(name_or_path)
    path = Path(text).expanduser()
    # a path has a known suffix or a slash; anything else is a built-in name (a stray
    # file or folder called "ur5" in the working directory must not hide the robot)
    suffix = loader_suffix(path)
    if suffix is not None or "/" in text or "\\" in text:
        if path.is_dir():
            raise SpecError(f"{text}: is a directory, expected a robot YAML or URDF file")
        if not path.is_file():
            raise SpecError(f"{text}: no such robot file")
        if suffix is None:
            raise SpecError(
                f"{text}: unknown robot file type '{path.suffix}'; valid: {', '.join(LOADERS)}"
            )
        try:
            content = path.read_bytes()
        except OSError as err:
            raise SpecError(f"{text}: cannot read robot file ({err})") from err
        sha256 = hashlib.sha256(content).hexdigest()
        return _load_file(str(path), str(path.resolve()), sha256, package_path)
    names = builtin_robot_names()
    if text not in names:
        hint = unknown_name_message("robot", text, names)
        raise SpecError(f"{hint} (or pass a path to a robot file: {', '.join(LOADERS)})")
    return _load_builtin(text)


@functools.lru_cache(maxsize=16)
def _load_file(path: str, resolved: str, sha256: str, package_path: tuple[str, ...]) -> RobotSpec:
    """A robot file, parsed once per process, place and content: ``resolved`` (the file's
    absolute path: a relative ``path`` names another file after a ``chdir``, with another
    sidecar and SRDF beside it) and ``sha256`` key the cache."""
    import importlib

    module, func = LOADERS[loader_suffix(Path(path)) or ""].split(":")
    loader = getattr(importlib.import_module(module), func)
    spec: RobotSpec = with_derived_accelerations(loader(Path(path), package_path=package_path))
    _check_names(spec, path)
    return dataclasses.replace(spec, source_sha256=sha256, loaded_from=path)


def _check_names(spec: RobotSpec, path: str) -> None:
    """The DH files' name rule (:data:`NAME_RULE`) for every format: the names end up in
    MJCF, URDF, /tf frames and file names."""
    named = [("robot", spec.name)]
    named += [("joint", j.name) for j in spec.joints] + [("link", j.link_name) for j in spec.joints]
    named += [("link", spec.base_link)] + [("frame", f.name) for f in spec.frames]
    for what, name in named:
        try:
            check_name(name)
        except ValueError:
            raise SpecError(f"{path}: {what} name {name!r}: {NAME_RULE}") from None


@functools.lru_cache(maxsize=16)
def _load_builtin(name: str) -> RobotSpec:
    sidecar = resources.files("pipeline.robots") / f"{name}{BUILTIN_SIDECAR}"
    if sidecar.is_file():  # a URDF robot: its settings sidecar names the URDF
        from pipeline.robots.urdf_loader import load_sidecar

        spec = with_derived_accelerations(load_sidecar(Path(str(sidecar))))
        digest = hashlib.sha256(Path(spec.source).read_bytes()).hexdigest()
        return dataclasses.replace(spec, source_sha256=digest, loaded_from=name)
    content = (resources.files("pipeline.robots") / f"{name}.yaml").read_text(encoding="utf-8")
    return parse_dh_text(content, f"robots/{name}.yaml")
