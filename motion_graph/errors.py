"""The one error type users see for bad mocap input."""
from __future__ import annotations


class MocapFormatError(ValueError):
    """A mocap file could not be read. The message names the file and, when known, the line.

    Attributes:
        path: the file that failed.
        line: 1-based line number of the problem, or None when it concerns the whole file.
        problem: what is wrong, in words.
    """

    def __init__(self, path: str, problem: str, line: int | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.problem = problem
        where = f"{self.path}:{line}" if line is not None else self.path
        super().__init__(f"{where}: {problem}")


class LibraryFormatError(ValueError):
    """An action-library (or other project) file is missing, truncated, corrupted or of another version."""

    def __init__(self, path: str, problem: str) -> None:
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")
