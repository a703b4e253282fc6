"""The command line's root options, read before the CLI loads (``pipeline.__main__``) and
by the CLI itself (``pipeline.cli.main``): one place that knows them."""

from __future__ import annotations

from collections.abc import Sequence


def hoist_root_options(args: Sequence[str]) -> list[str]:
    """``args`` with the root command's options moved before the command.

    ``--debug`` and ``--package-path DIR`` (or ``--package-path=DIR``) are accepted anywhere
    on the line (``pipeline fk arm.urdf 0 0 --package-path ~/ws/src``), as users of
    ``ros2`` and ``colcon`` type them; a value that is itself an option is left alone.
    """
    front: list[str] = []
    rest: list[str] = []
    i = 0
    while i < len(args):
        arg = args[i]
        if arg == "--debug" or arg.startswith("--package-path="):
            front.append(arg)
        elif arg == "--package-path" and i + 1 < len(args) and not args[i + 1].startswith("-"):
            front += [arg, args[i + 1]]
            i += 1
        else:
            rest.append(arg)
        i += 1
    return [*front, *rest]


def command_name(args: Sequence[str]) -> str:
    """The subcommand's name: the first word after the root options (wherever they were
    typed) that is not an option; "" when there is none (``pipeline --help``)."""
    hoisted = hoist_root_options(args)
    i = 0
    while i < len(hoisted):
        if hoisted[i] == "--package-path":
            i += 2
        elif hoisted[i].startswith("-"):
            i += 1
        else:
            return hoisted[i]
    return ""
