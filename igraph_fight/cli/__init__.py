"""The igraph-fight command: a thin layer over the library.

Each command group lives in its own module of this package with a ``register(subparsers)``
function. Other installed packages add command groups through the entry-point group
``igraph_fight.commands`` (a ``register(subparsers)`` callable each; the tracker package adds
``tracker``), and physics bouts through ``igraph_fight.physics`` (``fight``: a callable taking the
parsed ``fight`` arguments). Nothing here imports those packages until the parser is built.

User errors end the command with exit code 2 and one line on stderr, ``igraph-fight: error:
...``, never a traceback: options out of range (checked by the argparse ``type=`` functions
below), unknown styles, unreadable or refused files (mocap, libraries, graphs, checkpoints),
observations outside the controller's contract, and other bad arguments (ValueError). Set
IGRAPH_FIGHT_TRACEBACK=1 to see the traceback of such an error.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
from importlib.metadata import entry_points
from typing import Callable, Sequence

#: environment variable: show the traceback of user errors (debugging)
TRACEBACK_ENV = "IGRAPH_FIGHT_TRACEBACK"


class UsageError(ValueError):
    """A command line the parser refuses (unknown option, value out of range): one line."""


class Parser(argparse.ArgumentParser):
    """argparse's parser whose errors raise UsageError (main prints one line) instead of printing
    the usage and exiting."""

    def error(self, message: str):  # type: ignore[override]
        cmd = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        raise UsageError(f"{cmd}{message} (see {self.prog} --help)")


# ----- option types: argparse ``type=`` functions (ArgumentTypeError: argparse names the option) ------
def _number(text: str) -> float:
    try:
        x = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(x):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return x


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None


def positive_float(text: str) -> float:
    """A finite number > 0 (seconds, frame rates, minutes, distances)."""
    x = _number(text)
    if x <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return x


def non_negative_float(text: str) -> float:
    """A finite number >= 0."""
    x = _number(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return x


def probability(text: str) -> float:
    """A number in [0, 1]."""
    x = _number(text)
    if not 0.0 <= x <= 1.0:
        raise argparse.ArgumentTypeError(f"must lie in [0, 1], got {text}")
    return x


def positive_int(text: str) -> int:
    """An integer >= 1 (counts: bouts, walks, workers, repetitions)."""
    x = _integer(text)
    if x < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return x


def non_negative_int(text: str) -> int:
    """An integer >= 0 (seeds, indices)."""
    x = _integer(text)
    if x < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text}")
    return x


def port(text: str) -> int:
    """A TCP port, 0..65535 (0: any free port)."""
    x = _integer(text)
    if not 0 <= x <= 65535:
        raise argparse.ArgumentTypeError(f"must be a port in 0..65535, got {text}")
    return x


def depth(text: str) -> int:
    """A min-max depth: an integer in 1..igraph_fight.controller.MAX_DEPTH."""
    from igraph_fight.controller import MAX_DEPTH
    x = _integer(text)
    if not 1 <= x <= MAX_DEPTH:
        raise argparse.ArgumentTypeError(f"must be an integer in 1..{MAX_DEPTH}, got {text}")
    return x


def depth_list(text: str) -> str:
    """Comma-separated depths ('' for none), each in 1..MAX_DEPTH; the text as given."""
    for x in text.split(","):
        if x.strip():
            depth(x.strip())
    return text


def gamma(text: str) -> float:
    """A discount per decision: a number in (0, 1]."""
    x = _number(text)
    if not 0.0 < x <= 1.0:
        raise argparse.ArgumentTypeError(f"must lie in (0, 1], got {text}")
    return x


def swap(text: str) -> tuple[float, str]:
    """``T:STYLE``: a time in seconds (>= 0) and a style; (T, STYLE)."""
    t, sep, style = text.partition(":")
    if not sep or not style.strip():
        raise argparse.ArgumentTypeError(f"expected T:STYLE (e.g. 30:outboxer), got {text!r}")
    try:
        x = float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected T:STYLE with T in seconds, got {text!r}") from None
    if not math.isfinite(x) or x < 0:
        raise argparse.ArgumentTypeError(f"the swap time must be a finite number of seconds >= 0, got {t!r}")
    return x, style.strip()


def check_swap(value, seconds: float, option: str = "--swap-a") -> tuple[float, str] | None:
    """The (time, style) of a swap option (a ``T:STYLE`` string or a parsed pair; None: no swap)
    checked against the bout's length and the style loaded (planner.StyleError otherwise); a
    ValueError when the swap falls after the bout's end."""
    if value is None:
        return None
    t, style = swap(value) if isinstance(value, str) else value
    if t >= seconds:
        raise ValueError(f"{option} {t:g}:{style}: the swap time lies beyond the bout's end ({seconds:g} s)")
    from planner import load_style
    load_style(style)
    return float(t), style

#: the built-in command groups, in the order ``--help`` lists them
BUILTIN_GROUPS = ("igraph_fight.cli.mocap", "igraph_fight.cli.graph", "igraph_fight.cli.fight",
                  "igraph_fight.cli.evaluate", "igraph_fight.cli.play", "igraph_fight.cli.export")
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

    parser = Parser(prog="igraph-fight", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for modname in BUILTIN_GROUPS:
        importlib.import_module(modname).register(sub)
    for ep in sorted(entry_points(group=COMMANDS_GROUP), key=lambda e: e.name):
        ep.load()(sub)
    return parser


def user_error_line(e: BaseException) -> str:
    """``igraph-fight: error: <message>`` on one line (a FileNotFoundError names its file)."""
    msg = str(e)
    if isinstance(e, OSError) and e.filename is not None and str(e.filename) not in msg:
        msg = f"{e.filename}: {msg}"
    msg = " ".join(msg.split()) or type(e).__name__
    return f"igraph-fight: error: {msg}"


#: what main reports as a user error (module docstring): every project error type is a ValueError
#: (MocapFormatError, LibraryFormatError and GraphFormatError, planner.StyleError,
#: igraph_fight.controller.ObservationError, igraph_fight.checkpoint.CheckpointError, UsageError)
USER_ERRORS = (ValueError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError)


def main(argv: Sequence[str] | None = None) -> int:
    """Run one igraph-fight command; exit code 2 and one line on stderr for a user error."""
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        rc = args.func(args)
    except USER_ERRORS as e:
        if os.environ.get(TRACEBACK_ENV, "") not in ("", "0"):
            raise
        print(user_error_line(e), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("igraph-fight: interrupted", file=sys.stderr)
        return 130
    return int(rc or 0)


if __name__ == "__main__":
    sys.exit(main())
