"""The igraph-fight command: a thin layer over the library.

Each command group lives in its own module with a ``register(subparsers)`` function; the
tracker's commands are registered from the tracker package (imported only when used).
"""
from __future__ import annotations

import argparse
import sys
from typing import Sequence

from motion_graph.errors import LibraryFormatError, MocapFormatError


def build_parser() -> argparse.ArgumentParser:
    from . import cli_mocap

    parser = argparse.ArgumentParser(prog="igraph-fight", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    cli_mocap.register(sub)
    for modname in ("igraph_fight.cli_graph", "igraph_fight.cli_fight", "igraph_fight.cli_eval", "tracker.cli"):
        try:
            mod = __import__(modname, fromlist=["register"])
        except ModuleNotFoundError as e:
            # an optional command group that is not installed; real import errors inside it propagate
            if e.name is None or not modname.startswith(e.name):
                raise
            continue
        mod.register(sub)
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
