"""Keeping numba's on-disk kernel cache consistent across modules.

numba's ``cache=True`` checks only the source file of the cached function: a kernel that calls
(and inlines) kernels of other modules keeps machine code compiled against their old versions
after those files change. ``drop_stale_caches(__file__, deps)``, called by such a module before
its kernels first run, removes the module's cache files that are older than any of the source
files its kernels call into, so numba compiles them afresh.
"""
from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType


def drop_stale_caches(module_file: str | os.PathLike, deps: list[ModuleType]) -> int:
    """Remove ``module_file``'s numba cache files (``__pycache__/<stem>.*.nbi|nbc``, or under
    ``$NUMBA_CACHE_DIR``) older than the newest source file of ``deps``; returns how many went."""
    mod = Path(module_file)
    try:
        newest = max(Path(d.__file__).stat().st_mtime for d in deps)
    except (OSError, TypeError, ValueError):
        return 0
    pattern = f"{mod.stem}.*.nb[ic]"
    found = list((mod.parent / "__pycache__").glob(pattern))
    env = os.environ.get("NUMBA_CACHE_DIR")
    if env and Path(env).is_dir():
        found += [f for f in Path(env).rglob(pattern) if mod.parent.name in f.parts]
    n = 0
    for f in found:
        try:
            if f.stat().st_mtime < newest:
                f.unlink()
                n += 1
        except OSError:       # another process removed or rewrote it first
            pass
    return n
