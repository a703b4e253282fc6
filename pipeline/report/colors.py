"""One colour per controller, the same in every figure, the .rrd and the DVC plots.

A controller class may declare its colour (``COLOR``; the built-ins do, and ``make sync``
writes them into the DVC plot template ``.dvc/plots/controller_joint.json``); any other
controller name takes the next unused palette colour in sorted order. The colours are read
from :mod:`pipeline.control.info` (no controller is imported).
"""

from __future__ import annotations

from collections.abc import Iterable

from pipeline.control.info import builtin_info, declared_color

# Matplotlib's tab10, then tab20's light shades (the built-ins take most of tab10), as RGB.
PALETTE: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
    (174, 199, 232),
    (255, 187, 120),
    (152, 223, 138),
    (255, 152, 150),
    (197, 176, 213),
    (196, 156, 148),
    (247, 182, 210),
    (219, 219, 141),
    (158, 218, 229),
)
# What a key calls each palette colour.
PALETTE_NAMES = (
    "blue", "orange", "green", "red", "purple", "brown", "pink", "grey", "olive", "cyan",
    "light blue", "light orange", "light green", "light red", "light purple", "light brown",
    "light pink", "light olive", "light cyan",
)  # fmt: skip
# The built-in controllers' declared colours, by name.
FIXED: dict[str, tuple[int, int, int]] = {
    name: info.color for name, info in sorted(builtin_info().items()) if info.color is not None
}
# The reference: light grey, visible on Rerun's dark theme and on white.
REFERENCE_RGB = (200, 200, 200)
REFERENCE_MPL = "0.25"


def controller_colors(names: Iterable[str]) -> dict[str, tuple[int, int, int]]:
    """Colour of each controller name (declared ones first, then the rest in sorted order)."""
    out: dict[str, tuple[int, int, int]] = {}
    for name in sorted(set(names)):
        color = declared_color(name)
        if color is not None:
            out[name] = color
    taken = {*FIXED.values(), *out.values()}
    free = [c for c in PALETTE if c not in taken] or list(PALETTE)
    for k, name in enumerate(sorted(n for n in set(names) if n not in out)):
        out[name] = free[k % len(free)]
    return out


def color_name(rgb: tuple[int, int, int]) -> str:
    """A word for ``rgb``: its palette name, the nearest one's for another colour ("light
    grey" for the reference)."""
    if rgb == REFERENCE_RGB:
        return "light grey"
    k = min(
        range(len(PALETTE)),
        key=lambda i: sum((a - b) ** 2 for a, b in zip(PALETTE[i], rgb, strict=True)),
    )
    return PALETTE_NAMES[k]


def hex_color(rgb: tuple[int, int, int]) -> str:
    """``#rrggbb``."""
    return "#{:02x}{:02x}{:02x}".format(*rgb)


def mpl(rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    """Matplotlib's 0..1 RGB."""
    return (rgb[0] / 255, rgb[1] / 255, rgb[2] / 255)
