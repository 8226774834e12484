"""Per-edge columns allocated once and filled block by block, in memory or on disk.

    store = ColumnStore(folder)               # or ColumnStore(None): plain numpy arrays
    col = store.new("feat_r", n, np.float64)  # a memory-mapped file folder/feat_r.f8 when folder is set
    col[lo:hi] = block["r"]                   # each block written once, where it goes
    app = store.appender("cand", np.int32)    # a column of unknown length, grown at its end
    app.append(block_values)
    cols = store.finish()                     # name -> read-only array (np.memmap on disk)

The edge-linking stage knows how many edges survive before it simulates their features, so every
column is allocated once at its final size and each block of features is written into its place
as it arrives from a worker: the build never holds the blocks and their concatenation side by side.
With a folder (the build's checkpoint folder) the columns are files mapped into memory: their
pages belong to the page cache, which the kernel writes back and reclaims under pressure, so the
edge set does not have to fit in the build process's resident memory. A column whose length is
known only at its end (the linking's candidates, the surviving edges) is an ``appender``: each block
is written at the end of its file (or kept as a block in memory) and mapped once finished.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np


class ColumnStore:
    """Columns of known length, each filled in place (module docstring)."""

    def __init__(self, folder: str | os.PathLike | None) -> None:
        self.folder = Path(folder) if folder is not None else None
        self.cols: dict[str, np.ndarray] = {}
        if self.folder is not None:
            self.folder.mkdir(parents=True, exist_ok=True)

    def path(self, name: str, dtype) -> Path:
        if self.folder is None:
            raise ValueError("an in-memory ColumnStore has no files")
        return self.folder / f"{name}.{np.dtype(dtype).str.lstrip('<>|=')}"

    def new(self, name: str, n: int, dtype) -> np.ndarray:
        """A writable column of ``n`` values of ``dtype`` (zeros on disk, uninitialised in memory)."""
        if name in self.cols:
            raise ValueError(f"column {name!r} allocated twice")
        if n < 0:
            raise ValueError(f"column {name!r}: negative length {n}")
        if self.folder is None or n == 0:
            a = np.empty(n, dtype=dtype)
        else:
            a = np.memmap(self.path(name, dtype), dtype=dtype, mode="w+", shape=(n,))
        self.cols[name] = a
        return a

    def appender(self, name: str, dtype) -> "Appender":
        """A column grown block by block at its end (module docstring)."""
        if name in self.cols:
            raise ValueError(f"column {name!r} allocated twice")
        a = Appender(self.path(name, dtype) if self.folder is not None else None, dtype)
        self.cols[name] = a
        return a

    def finish(self) -> dict[str, np.ndarray]:
        """The columns, read-only: files flushed and mapped again read-only."""
        out = {}
        for name, a in self.cols.items():
            if isinstance(a, Appender):
                out[name] = a.finish()
                self.cols[name] = None
            elif isinstance(a, np.memmap):
                a.flush()
                p, dt, n = self.path(name, a.dtype), a.dtype, len(a)
                del a
                self.cols[name] = None
                out[name] = np.memmap(p, dtype=dt, mode="r", shape=(n,))
            else:
                a.flags.writeable = False
                out[name] = a
        self.cols = {}
        return out


class Appender:
    """A column of ``dtype`` written block by block at its end: to the file ``path`` (then mapped
    read-only by ``finish``) or, without a path, kept as blocks and joined by ``finish``."""

    def __init__(self, path: Path | None, dtype) -> None:
        self.path, self.dtype = path, np.dtype(dtype)
        self.n = 0
        self.result: np.ndarray | None = None
        self.blocks: list[np.ndarray] = []
        self.fh = open(path, "wb") if path is not None else None

    def __len__(self) -> int:
        return self.n

    def append(self, x: np.ndarray) -> None:
        if self.result is not None:
            raise ValueError("an appender takes no block once finished")
        x = np.ascontiguousarray(x, dtype=self.dtype).reshape(-1)
        if self.fh is not None:
            self.fh.write(memoryview(x).cast("B"))
        else:
            self.blocks.append(x)
        self.n += len(x)

    def finish(self) -> np.ndarray:
        """The column, read-only (the same array when called again)."""
        if self.result is not None:
            return self.result
        if self.fh is None:
            a = np.concatenate(self.blocks) if self.blocks else np.zeros(0, self.dtype)
            self.blocks = []
            a.flags.writeable = False
        else:
            self.fh.close()
            self.fh = None
            a = np.memmap(self.path, dtype=self.dtype, mode="r", shape=(self.n,)) if self.n else np.zeros(0, self.dtype)
        self.result = a
        return a
