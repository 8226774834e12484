"""Crash-safe file writes, and the crash tests' kill hook.

``atomic_write`` writes to ``.<name>.tmp-<pid>-<8 hex>`` beside the target, fsyncs it, renames it
over the target and fsyncs the folder: a reader (or a rerun after a crash) sees the old file or
the new one, never a part of one, and once it returns the new file survives a power loss.
Temporary files of writers that were killed are removed by the next write to the same path: only
files of exactly that naming whose process ``<pid>`` no longer runs on this machine.

Test hook: ``kill_point(stage)`` SIGKILLs the process when the environment variable
IGRAPH_FIGHT_TEST_KILL_AT names that stage (``STAGE`` or ``STAGE@N``: the Nth time the process
reaches it). Only the crash-safety tests set it; the stages are listed where they are reached
(igraph_fight.build.pipeline, igraph_fight.graph's save).
"""
from __future__ import annotations

import os
import re
import secrets
import signal
from pathlib import Path
from typing import Callable

#: environment variable of the crash tests' kill hook (see the module docstring)
KILL_ENV = "IGRAPH_FIGHT_TEST_KILL_AT"
_reached: dict[str, int] = {}


def kill_point(stage: str) -> None:
    """Test hook: SIGKILL this process here when $IGRAPH_FIGHT_TEST_KILL_AT is ``stage`` or
    ``stage@N`` and this is the Nth time the process reaches ``stage`` (default: the first)."""
    want = os.environ.get(KILL_ENV)
    if not want:
        return
    name, _, nth = want.partition("@")
    if name != stage:
        return
    _reached[stage] = _reached.get(stage, 0) + 1
    if _reached[stage] >= int(nth or 1):
        os.kill(os.getpid(), signal.SIGKILL)


def temp_path(path: str | os.PathLike) -> Path:
    """A fresh temporary name beside ``path`` for this process: ``.<name>.tmp-<pid>-<8 hex>``."""
    path = Path(path)
    return path.parent / f".{path.name}.tmp-{os.getpid()}-{secrets.token_hex(4)}"


def _running(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # a process of another user
        return True
    except (OverflowError, ValueError):
        return False
    return True


def stale_temp_files(path: str | os.PathLike) -> list[Path]:
    """Temporary files of interrupted atomic writes to ``path`` whose writer no longer runs."""
    path = Path(path)
    pattern = re.compile(re.escape(f".{path.name}.tmp-") + r"([0-9]{1,10})-[0-9a-f]{8}")
    try:
        names = os.listdir(path.parent)
    except OSError:
        return []
    out = []
    for n in sorted(names):
        m = pattern.fullmatch(n)
        if m and int(m.group(1)) > 0 and not _running(int(m.group(1))):
            out.append(path.parent / n)
    return out


def remove_stale_temp_files(path: str | os.PathLike) -> list[Path]:
    """Delete stale_temp_files(path); returns the ones removed."""
    removed = []
    for p in stale_temp_files(path):
        try:
            p.unlink()
            removed.append(p)
        except OSError:
            pass
    return removed


def fsync_dir(folder: str | os.PathLike) -> None:
    """fsync a folder, so that renames and deletions in it are durable (no-op where unsupported)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write(path: str | os.PathLike, write: Callable[[object], None], mode: str = "wb") -> None:
    """Call write(fileobj) on a temporary file beside path, then atomically replace path with it
    (file and folder fsynced); stale temporary files of earlier writes to path are removed first."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temp_files(path)
    tmp = temp_path(path)
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)  # the umask applies
    try:
        with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8"})) as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    fsync_dir(path.parent)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """atomic_write of a text (UTF-8)."""
    atomic_write(path, lambda fh: fh.write(text), mode="w")


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """atomic_write of bytes."""
    atomic_write(path, lambda fh: fh.write(data), mode="wb")
