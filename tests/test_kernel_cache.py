"""numba's cache checks only a kernel's own file: drop_stale_caches removes a module's cache
files older than the modules its kernels call into, and keeps the fresh ones."""
from __future__ import annotations

import os
import types

from igraph_fight.kernel_cache import drop_stale_caches


def test_cache_files_older_than_a_dependency_are_dropped(tmp_path, monkeypatch):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    mod = tmp_path / "search.py"
    dep = tmp_path / "locate.py"
    mod.write_text("")
    dep.write_text("")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    old = [cache / "search.kernel-10.py311.nbi", cache / "search.kernel-10.py311.1.nbc"]
    other = cache / "sim.kernel-5.py311.nbi"                  # another module's cache: not ours to drop
    for f in (*old, other):
        f.write_text("")
        os.utime(f, (1_000, 1_000))
    os.utime(dep, (2_000, 2_000))
    dep_module = types.SimpleNamespace(__file__=str(dep))
    assert drop_stale_caches(mod, [dep_module]) == 2
    assert not any(f.exists() for f in old) and other.exists()
    fresh = cache / "search.kernel-10.py311.nbi"
    fresh.write_text("")
    os.utime(fresh, (3_000, 3_000))
    assert drop_stale_caches(mod, [dep_module]) == 0 and fresh.exists()
    assert drop_stale_caches(mod, [types.SimpleNamespace(__file__=str(tmp_path / "missing.py"))]) == 0
