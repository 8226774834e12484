"""The igraph-fight command: a thin layer over the library.

Each command group lives in its own module of this package with a ``register(subparsers)``
function. Other installed packages add command groups through the entry-point group
``igraph_fight.commands`` (a ``register(subparsers)`` callable each; the tracker package adds
``tracker``), and physics bouts through ``igraph_fight.physics`` (``fight``: a callable taking the
parsed ``fight`` arguments). Nothing here imports those packages until the parser is built.
"""
from __future__ import annotations

import argparse
import sys
from importlib.metadata import entry_points
from typing import Callable, Sequence

from motion_graph.errors import LibraryFormatError, MocapFormatError

#: the built-in command groups, in the order ``--help`` lists them
BUILTIN_GROUPS = ("igraph_fight.cli.mocap", "igraph_fight.cli.graph", "igraph_fight.cli.fight",
                  "igraph_fight.cli.evaluate")
COMMANDS_GROUP = "igraph_fight.commands"
PHYSICS_GROUP = "igraph_fight.physics"


def plugin(group: str, name: str) -> Callable | None:
    """The entry point ``name`` of ``group`` loaded, or None when no installed package provides it."""
    for ep in entry_points(group=group):
        if ep.name == name:
            return ep.load()
    return None


def build_parser() -> argparse.ArgumentParser:
    import importlib

    parser = argparse.ArgumentParser(prog="igraph-fight", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for modname in BUILTIN_GROUPS:
        importlib.import_module(modname).register(sub)
    for ep in sorted(entry_points(group=COMMANDS_GROUP), key=lambda e: e.name):
        ep.load()(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        rc = args.func(args)
    except (MocapFormatError, LibraryFormatError) as e:
        print(f"igraph-fight: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("igraph-fight: interrupted", file=sys.stderr)
        return 130
    return int(rc or 0)


if __name__ == "__main__":
    sys.exit(main())
