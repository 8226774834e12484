"""Per-edge columns allocated once and filled block by block, in memory or on disk.

    store = ColumnStore(folder)               # or ColumnStore(None): plain numpy arrays
    col = store.new("feat_r", n, np.float64)  # a memory-mapped file folder/feat_r.f8 when folder is set
    col[lo:hi] = block["r"]                   # each block written once, where it goes
    cols = store.finish()                     # name -> read-only array (np.memmap on disk)

The edge-linking stage knows how many edges survive before it simulates their features, so every
column is allocated once at its final size and each block of features is written into its place
as it arrives from a worker: the build never holds the blocks and their concatenation side by side.
With a folder (the build's checkpoint folder) the columns are files mapped into memory: their
pages belong to the page cache, which the kernel writes back and reclaims under pressure, so the
edge set does not have to fit in the build process's resident memory.
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

    def finish(self) -> dict[str, np.ndarray]:
        """The columns, read-only: files flushed and mapped again read-only."""
        out = {}
        for name, a in self.cols.items():
            if isinstance(a, np.memmap):
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
