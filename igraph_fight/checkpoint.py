"""Checkpoint files: torch files read weights-only, with a named and versioned payload.

    save_checkpoint("rl.pt", ck, format="igraph-fight/rl-ppo", version=2)      # atomic
    ck = load_checkpoint("rl.pt", format="igraph-fight/rl-ppo", versions=(2,))  # CheckpointError otherwise

A checkpoint is a dict with a ``format`` entry (the kind of checkpoint, a string) and a ``version``
entry (an int) beside its content. Every file is read with ``torch.load(weights_only=True)``:
unpickling builds only tensors and plain containers (dict, list, tuple, str, int, float, bool,
None) and never imports or calls anything else, so a crafted file cannot run code; anything else
in it is refused with a CheckpointError. ``save_checkpoint`` stores numpy arrays as tensors of the
same dtype and values (readers take them back with ``np.asarray``), numpy scalars as Python
numbers and str subclasses (e.g. ``torch.__version__``) as str, and refuses other objects; it
writes through motion_graph.atomic (a reader sees the old file or the new one, never a part).

The formats of the project's checkpoints (and what each version means) are listed in
igraph_fight/checkpoints/README.md and tracker/checkpoints/README.md. Files written before these
formats (pickles holding numpy arrays or torch version objects, or no format entry) do not load;
``python -m igraph_fight.checkpoint convert OLD NEW --format F --version V`` rewrites a file you
trust in the current form: it reads it weights-only with numpy arrays and torch's version string
as the only extra types allowed, so even that conversion runs no code from the file.
"""
from __future__ import annotations

import argparse
import os
import re
import sys
from collections import OrderedDict
from pathlib import Path
from typing import Any, Sequence

from motion_graph.errors import LibraryFormatError


class CheckpointError(LibraryFormatError):
    """A checkpoint file is missing, unreadable, holds anything but tensors and plain values, or is
    of another format or version. The message (one line) names the file."""


#: what a legacy file may contain beyond weights-only types (``convert``): numpy arrays, torch's version
LEGACY_GLOBALS = ("numpy.ndarray", "numpy.dtype", "numpy._core.multiarray._reconstruct",
                  "numpy.core.multiarray._reconstruct", "torch.torch_version.TorchVersion",
                  *(f"numpy.dtypes.{t}DType" for t in ("Bool", "Int8", "Int16", "Int32", "Int64", "UInt8", "UInt16",
                                                       "UInt32", "UInt64", "Float16", "Float32", "Float64")))


def _one_line(e: BaseException) -> str:
    """The first line of an exception's message, with its type (torch's messages run to pages)."""
    text = str(e).strip().splitlines()
    return f"{type(e).__name__}: {text[0] if text else ''}".rstrip(": ")


def plain(obj: Any, where: str = "checkpoint") -> Any:
    """``obj`` with numpy arrays as tensors, numpy scalars as Python numbers and subclasses of
    str / int / float as those types, containers converted recursively (a container with nothing
    to convert is returned as it is); a TypeError naming the entry for anything else."""
    import numpy as np
    import torch

    if obj is None or type(obj) in (bool, int, float, str) or isinstance(obj, torch.Tensor):
        return obj
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind not in "biuf":
            raise TypeError(f"{where}: numpy array of dtype {obj.dtype} (only numbers can be stored)")
        return torch.from_numpy(np.ascontiguousarray(obj).copy())
    if isinstance(obj, np.generic):
        if obj.dtype.kind not in "biuf":
            raise TypeError(f"{where}: numpy scalar of dtype {obj.dtype}")
        return obj.item()
    for t in (bool, int, float, str):           # subclasses: IntEnum, torch's TorchVersion, ...
        if isinstance(obj, t):
            return t(obj)
    if isinstance(obj, dict):
        items = [(plain(k, f"{where} key"), plain(v, f"{where}[{k!r}]")) for k, v in obj.items()]
        if all(k2 is k and v2 is v for (k2, v2), (k, v) in zip(items, obj.items())):
            return obj
        out = type(obj)(items) if type(obj) in (dict, OrderedDict) else dict(items)
        if hasattr(obj, "_metadata"):           # a torch state dict's module versions
            out._metadata = obj._metadata
        return out
    if isinstance(obj, (list, tuple)):
        items = [plain(v, f"{where}[{i}]") for i, v in enumerate(obj)]
        if type(obj) in (list, tuple) and all(a is b for a, b in zip(items, obj)):
            return obj
        return items if isinstance(obj, list) else tuple(items)
    raise TypeError(f"{where}: {type(obj).__module__}.{type(obj).__qualname__} cannot be stored in a checkpoint "
                    "(tensors, numpy arrays, dict, list, tuple, str, int, float, bool, None only)")


def save_checkpoint(path: str | os.PathLike, payload: dict, format: str, version: int) -> Path:
    """Write ``payload`` with ``format`` and ``version`` entries to ``path`` atomically (module
    docstring: what is converted, what is refused). Returns the path."""
    import torch

    from motion_graph.atomic import atomic_write

    if not isinstance(payload, dict):
        raise TypeError(f"a checkpoint is a dict, not {type(payload).__name__}")
    ck = plain({**payload, "format": str(format), "version": int(version)})
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(path, lambda fh: torch.save(ck, fh))
    return path


def _read(path: Path, extra_globals: Sequence = ()) -> Any:
    import torch

    if not path.is_file():
        raise CheckpointError(str(path), "no such file" if not path.exists() else "not a file")
    try:
        if extra_globals:
            with torch.serialization.safe_globals(list(extra_globals)):
                return torch.load(str(path), map_location="cpu", weights_only=True)
        return torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - torch raises many types; the file is what is wrong
        msg = _one_line(e)
        m = re.search(r"GLOBAL ([\w.]+)|but got <class '([\w.]+)'>", str(e))
        if m or "Weights only load failed" in str(e):
            msg = (f"it holds objects other than tensors and plain values ({(m.group(1) or m.group(2)) if m else 'unknown'}), "
                   "refused unread (convert an old checkpoint you trust: python -m igraph_fight.checkpoint convert)")
        raise CheckpointError(str(path), f"not a loadable checkpoint: {msg}") from None


def load_checkpoint(path: str | os.PathLike, format: str, versions: Sequence[int], what: str | None = None) -> dict:
    """The checkpoint dict at ``path``, read weights-only; a CheckpointError (one line, naming the
    file) when it is missing, unreadable, holds anything but tensors and plain values, or its
    ``format`` is not ``format`` or its ``version`` not one of ``versions``. ``what``: the kind of
    checkpoint in the messages (default: the format name)."""
    p = Path(path)
    ck = _read(p)
    what = what or format
    if not isinstance(ck, dict):
        raise CheckpointError(str(p), f"not a {what} checkpoint (a {type(ck).__name__}, not a dict)")
    got = ck.get("format")
    if got != format:
        hint = ("no format entry: written before checkpoints were versioned; convert a file you trust with "
                f"python -m igraph_fight.checkpoint convert --format {format}") if got is None else f"format {got!r}"
        raise CheckpointError(str(p), f"not a {what} checkpoint ({hint})")
    v = ck.get("version")
    if type(v) is not int or v not in tuple(versions):
        raise CheckpointError(str(p), f"{what} checkpoint version {v!r}, this version reads "
                                      f"{', '.join(str(x) for x in versions)}")
    return ck


def convert(src: str | os.PathLike, dst: str | os.PathLike, format: str | None = None,
            version: int | None = None) -> dict:
    """Rewrite a checkpoint you trust, written before these formats, in the current form: read
    weights-only with numpy arrays and torch's version string also allowed (LEGACY_GLOBALS, so no
    code from the file runs), their values kept, the ``format`` / ``version`` entries set (default:
    the file's own). Writes ``dst`` atomically; returns the converted dict."""
    import importlib

    allowed = []
    for name in LEGACY_GLOBALS:
        mod, _, attr = name.rpartition(".")
        try:
            allowed.append(getattr(importlib.import_module(mod), attr))
        except (ImportError, AttributeError):
            continue
    ck = _read(Path(src), allowed)
    if not isinstance(ck, dict):
        raise CheckpointError(str(src), f"not a checkpoint (a {type(ck).__name__}, not a dict)")
    fmt = format if format is not None else ck.get("format")
    ver = version if version is not None else ck.get("version")
    if not isinstance(fmt, str) or type(ver) is not int:
        raise CheckpointError(str(src), "no format / version entry: give --format and --version")
    try:
        save_checkpoint(dst, ck, fmt, ver)
    except TypeError as e:
        raise CheckpointError(str(src), str(e)) from None
    return plain({**ck, "format": fmt, "version": ver})


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m igraph_fight.checkpoint convert OLD NEW [--format F] [--version V]``."""
    ap = argparse.ArgumentParser(prog="python -m igraph_fight.checkpoint", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("convert", help="rewrite a trusted pre-format checkpoint weights-only (no code runs)")
    c.add_argument("src")
    c.add_argument("dst")
    c.add_argument("--format", default=None, help="format name to record (default: the file's)")
    c.add_argument("--version", type=int, default=None, help="format version to record (default: the file's)")
    a = ap.parse_args(argv)
    try:
        ck = convert(a.src, a.dst, a.format, a.version)
    except CheckpointError as e:
        print(f"igraph-fight: error: {e}", file=sys.stderr)
        return 2
    print(f"wrote {a.dst}: {ck['format']} version {ck['version']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
