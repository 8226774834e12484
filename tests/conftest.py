"""Shared test fixtures: where the real mocap lives."""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

# Make the repo importable when the package is not installed in the venv (plain `pytest` run).
_REPO = str(Path(__file__).resolve().parent.parent)
if _REPO not in sys.path:
    sys.path.insert(0, _REPO)

from motion_graph import paths  # noqa: E402


def _mocap_root_or_skip() -> Path:
    root = paths.find_mocap_root()
    if root is None or not root.is_dir():
        msg = (f"real mocap not found (set {paths.ENV_VAR} or put it at ../shared/mocap; "
               f"looked at {root or ', '.join(map(str, paths.candidate_mocap_roots()))})")
        if os.environ.get("CI") == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return root


@pytest.fixture(scope="session")
def mocap_root() -> Path:
    """The real mocap folder (paths.find_mocap_root()); fails on CI, skips elsewhere when missing."""
    return _mocap_root_or_skip()


@pytest.fixture(scope="session")
def boxing_files(mocap_root: Path) -> list[Path]:
    """The two CMU boxing takes as BVH: cmu/boxing/13_17.bvh and 13_18.bvh."""
    files = [mocap_root / "cmu" / "boxing" / f"13_{t}.bvh" for t in (17, 18)]
    missing = [str(f) for f in files if not f.is_file()]
    if missing:
        msg = f"CMU boxing BVH missing: {', '.join(missing)}"
        if os.environ.get("CI") == "true":
            pytest.fail(msg)
        pytest.skip(msg)
    return files
