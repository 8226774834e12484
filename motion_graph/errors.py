"""Bad input: the error types users see, the caps on what a mocap file may hold, and the text
reading and ASCII number grammar the mocap loaders share.

Every problem in a mocap file is a :class:`MocapFormatError` naming the file (and the line when
known) with a one-line message that quotes at most :data:`QUOTE_CHARS` characters of the file.
"""
from __future__ import annotations

import math
import os
import re
import stat
from collections.abc import Iterator

import numpy as np

MAX_FILE_BYTES = 256 * 1024 * 1024
"""Largest mocap file read, in bytes (256 MiB; the largest shared clip has 4 MB)."""

MAX_JOINTS = 5_000
"""Most joints a skeleton may have, end sites included (the shared clips have 27 and 38)."""

MAX_CHANNELS = 10_000
"""Most animated channels (values per frame) a BVH hierarchy may declare (shared clips: 96, 132)."""

MAX_FRAMES = 1_000_000
"""Most frames a clip may have (2.3 hours at 120 fps; the longest shared clip has 5,424)."""

MAX_FRAME_JOINTS = 10_000_000
"""Most frames x joints a clip may have: the loaders hold a few arrays of this many rotations and
translations, under 100 bytes each (a 2,000-frame BVH of 5,000 joints, at the cap, loads with a
0.8 GB peak; the largest shared clip has 5,424 x 38 = 206,112)."""

MIN_FRAME_TIME_S = 1e-4
"""Shortest frame time accepted, seconds (10,000 fps). Frame rates given by the caller are held
to the same range, MIN_FPS to MAX_FPS."""

MAX_FRAME_TIME_S = 10.0
"""Longest frame time accepted, seconds (0.1 fps)."""

MIN_FPS = 1.0 / MAX_FRAME_TIME_S
"""Lowest frame rate accepted (from a header or given by the caller), frames per second."""

MAX_FPS = 1.0 / MIN_FRAME_TIME_S
"""Highest frame rate accepted, frames per second."""

MAX_ABS_LENGTH = 1e7
"""Largest magnitude of any length or position, in file units and in metres once scaled (10,000 km
in metres, 10 km in millimetres): beyond it the file is corrupt, and forward kinematics over
MAX_JOINTS joints stays finite."""

MAX_NAME_CHARS = 1_000
"""Longest joint or bone name accepted, characters."""

QUOTE_CHARS = 80
"""Most characters of file text an error message quotes ('...' marks a cut)."""

#: An ASCII decimal number: optional sign, digits with an optional fraction (or a bare fraction),
#: optional exponent. Possessive quantifiers keep matching linear in the text's length.
FLOAT_PATTERN = r"[+-]?+(?:[0-9]++(?:\.[0-9]*+)?+|\.[0-9]++)(?:[eE][+-]?+[0-9]++)?+"
_FLOAT = re.compile(FLOAT_PATTERN)
_NON_FINITE = re.compile(r"[+-]?(?:inf|infinity|nan)", re.IGNORECASE)
_WHOLE = re.compile(r"[0-9]++")
_TOKEN = re.compile(r"\S+")
#: Numbers separated by spaces or tabs, nothing else: the fast check of a BVH frame or AMC bone line.
_NUMBER_ROW = re.compile(rf"[ \t]*+{FLOAT_PATTERN}(?:[ \t]++{FLOAT_PATTERN})*+[ \t]*+")
#: Whole numbers are read up to this many significant digits; larger ones read as 10**WHOLE_DIGITS.
WHOLE_DIGITS = 18


class MocapFormatError(ValueError):
    """A mocap file could not be read. The message names the file and, when known, the line.

    Attributes:
        path: the file that failed.
        line: 1-based line number of the problem, or None when it concerns the whole file.
        problem: what is wrong, in words (one line).
    """

    def __init__(self, path: str, problem: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.problem = " ".join(problem.splitlines())
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {self.problem}")


class LibraryFormatError(ValueError):
    """An action-library (or other project) file is missing, truncated, corrupted or of another version."""

    def __init__(self, path: str, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


def quote(text: str, limit: int = QUOTE_CHARS) -> str:
    """repr() of at most ``limit`` characters of text, followed by '...' when cut."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + "..."


def shorten(text: str, limit: int) -> str:
    """text cut to ``limit`` characters, ending in '...' when cut."""
    return text if len(text) <= limit else text[:limit] + "..."


def read_mocap_text(path: str) -> str:
    """The text of a mocap file: UTF-8 (a leading BOM dropped, undecodable bytes replaced), line
    ends (CRLF, CR) turned into LF.

    Raises:
        MocapFormatError: unreadable, larger than MAX_FILE_BYTES, or empty (whitespace only).
    """
    too_large = MocapFormatError(path, f"file larger than {MAX_FILE_BYTES:,} bytes (motion_graph.errors.MAX_FILE_BYTES)")
    try:
        with open(path, "rb") as f:
            info = os.fstat(f.fileno())
            if stat.S_ISREG(info.st_mode):
                if info.st_size > MAX_FILE_BYTES:
                    raise too_large
                data = f.read(MAX_FILE_BYTES + 1) if info.st_size == 0 else f.read()
            else:  # a pipe or device: read at most the cap, in pieces
                pieces, total = [], 0
                while total <= MAX_FILE_BYTES and (piece := f.read(1 << 20)):
                    pieces.append(piece)
                    total += len(piece)
                data = b"".join(pieces)
    except OSError as e:
        raise MocapFormatError(path, f"cannot read file: {e.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise too_large
    text = data.decode("utf-8-sig", errors="replace")
    del data
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    if not text.strip():
        raise MocapFormatError(path, "empty file")
    return text


def line_count(text: str) -> int:
    """Number of lines numbered_lines(text) yields."""
    return text.count("\n") + (0 if not text or text.endswith("\n") else 1)


def numbered_lines(text: str) -> Iterator[tuple[int, str]]:
    """(1-based line number, line) for each line of an LF-ended text (read_mocap_text's)."""
    start, n, ln = 0, len(text), 0
    while start < n:
        end = text.find("\n", start)
        if end < 0:
            end = n
        ln += 1
        yield ln, text[start:end]
        start = end + 1


def count_tokens(text: str) -> int:
    """Number of whitespace-separated tokens in text (what len(text.split()) gives, without the list)."""
    return sum(1 for _ in _TOKEN.finditer(text))


def parse_float(token: str) -> float | None:
    """An ASCII decimal number (``-1.5``, ``.5``, ``2e-3``) as a float; ``nan``, ``inf`` and
    ``infinity`` (any case, optional sign) as nan / inf; None for anything else (``1_0``,
    full-width or other non-ASCII digits, hexadecimal, empty)."""
    if _FLOAT.fullmatch(token) or _NON_FINITE.fullmatch(token):
        return float(token)
    return None


def is_number_row(line: str) -> bool:
    """True when line holds only ASCII decimal numbers separated by spaces or tabs."""
    return _NUMBER_ROW.fullmatch(line) is not None


def parse_whole(token: str) -> int | None:
    """An unsigned ASCII whole number (``4840``) as an int, at most ``10**WHOLE_DIGITS`` (larger
    numbers read as that); None for anything else (signs, superscripts, other digits)."""
    if not _WHOLE.fullmatch(token):
        return None
    digits = token.lstrip("0") or "0"
    return 10 ** WHOLE_DIGITS if len(digits) > WHOLE_DIGITS else int(digits)


def number_error(path: str, token: str, what: str, line: int | None) -> MocapFormatError:
    """The error for a token that is not a finite number: non-numeric or non-finite."""
    kind = "non-finite" if _NON_FINITE.fullmatch(token) else "non-numeric"
    return MocapFormatError(path, f"{kind} value {quote(token)} in {what}", line)


def parse_finite(path: str, tokens: list[str], what: str, line: int | None,
                 limit: float | None = MAX_ABS_LENGTH) -> list[float]:
    """tokens as finite floats, each within +-limit when limit is given.

    Raises:
        MocapFormatError: a token is not an ASCII decimal number, is nan/inf, overflows, or is
            larger than limit.
    """
    out = []
    for t in tokens:
        v = parse_float(t)
        if v is None or not math.isfinite(v):
            if v is not None and _FLOAT.fullmatch(t):
                raise MocapFormatError(path, f"value {quote(t)} in {what} overflows", line)
            raise number_error(path, t, what, line)
        if limit is not None and abs(v) > limit:
            raise MocapFormatError(path, f"value {quote(t)} in {what} exceeds {limit:g} "
                                         f"(motion_graph.errors.MAX_ABS_LENGTH)", line)
        out.append(v)
    return out


def check_rate(path: str, fps: float, what: str = "fps") -> float:
    """fps as a float when it is finite and within MIN_FPS..MAX_FPS.

    Raises:
        MocapFormatError (a ValueError) naming path otherwise.
    """
    try:
        v = float(fps)
    except (TypeError, ValueError):
        raise MocapFormatError(path, f"{what} must be a number, got {quote(str(fps))}") from None
    if not (math.isfinite(v) and MIN_FPS <= v <= MAX_FPS):
        raise MocapFormatError(path, f"{what} must be a finite frame rate in {MIN_FPS:g}..{MAX_FPS:g} "
                                     f"frames/s, got {v!r}")
    return v


def check_scale(path: str, metres_per_unit: float) -> float:
    """metres_per_unit as a float when finite and positive.

    Raises:
        MocapFormatError (a ValueError) naming path otherwise.
    """
    try:
        v = float(metres_per_unit)
    except (TypeError, ValueError):
        raise MocapFormatError(path, f"metres_per_unit must be a number, got {quote(str(metres_per_unit))}") from None
    if not (math.isfinite(v) and v > 0):
        raise MocapFormatError(path, f"metres_per_unit must be finite and positive, got {v!r}")
    return v


def check_lengths(path: str, values: np.ndarray, what: str) -> None:
    """Raise MocapFormatError unless every value is finite and within +-MAX_ABS_LENGTH."""
    if values.size and not (np.isfinite(values).all() and float(np.abs(values).max()) <= MAX_ABS_LENGTH):
        raise MocapFormatError(path, f"{what} not finite or beyond {MAX_ABS_LENGTH:g} "
                                     f"(motion_graph.errors.MAX_ABS_LENGTH)")
