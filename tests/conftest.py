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

from motion_graph import paths


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


# ---- a small real Interaction Graph (controller, strategy swap, crowd, cooperative tests) ------
#: Samples of the session's small graph: seconds to build, yet enough states for bouts to stay
#: mostly near the graph. Tests that need a real graph share it (build once per session).
SMALL_GRAPH_SAMPLES = 40_000


@pytest.fixture(scope="session")
def small_graph(boxing_library):
    """(graph, library): an Interaction Graph of the CMU boxing library built with the default
    options but only SMALL_GRAPH_SAMPLES samples (seed 0, one thread: deterministic). Uses the
    session fixture ``boxing_library`` (defined below)."""
    from igraph_fight.build.pipeline import BuildOptions, build_graph
    graph, _ = build_graph(boxing_library, BuildOptions(max_samples=SMALL_GRAPH_SAMPLES, seed_bouts=0), seed=0, workers=1)
    return graph, boxing_library


@pytest.fixture(scope="session")
def boxing_library_file(boxing_library, tmp_path_factory) -> str:
    """The session's boxing library saved as an .npz (what the tracker's workers load)."""
    path = tmp_path_factory.mktemp("lib") / "boxing_library.npz"
    boxing_library.save(path)
    return str(path)


@pytest.fixture(scope="session")
def boxing_library(boxing_files):
    """The action library of the two CMU boxing takes (motion_graph.build_library, about 6 s)."""
    from motion_graph.library import build_library
    return build_library(boxing_files)


@pytest.fixture(scope="session")
def default_library(boxing_files, mocap_root):
    """The default action library: the shared boxing takes 13_17, 13_18 and 14_02 on 13_17's body
    (motion_graph.retarget.default_boxing_library, about 10 s); the shipped physics checkpoints
    that pick library actions are trained on it."""
    from motion_graph.retarget import default_boxing_library
    if not (mocap_root / "cmu" / "bvh_hahne" / "14_02.bvh").is_file():
        pytest.skip("CMU 14_02 missing")
    return default_boxing_library(mocap_root)


@pytest.fixture(scope="session")
def tiny_graph_file(boxing_library, tmp_path_factory) -> Path:
    """A tiny Interaction Graph of the boxing library (3000 samples, a few seconds), saved with
    its library embedded."""
    from igraph_fight.build.pipeline import BuildOptions, build_graph
    graph, _ = build_graph(boxing_library, BuildOptions(max_samples=3000, n_initial=16, chunk_parents=64, seed_bouts=0), seed=0)
    path = tmp_path_factory.mktemp("tiny_graph") / "tiny.igz"
    graph.save(path)
    return path


@pytest.fixture(scope="session")
def tiny_default_graph_file(default_library, tmp_path_factory) -> Path:
    """tiny_graph_file's options on the default library (13_17 + 13_18 + 14_02): the graph the
    shipped physics RL baseline and hit model fit."""
    from igraph_fight.build.pipeline import BuildOptions, build_graph
    graph, _ = build_graph(default_library, BuildOptions(max_samples=3000, n_initial=16, chunk_parents=64, seed_bouts=0),
                           seed=0)
    path = tmp_path_factory.mktemp("tiny_default_graph") / "tiny3.igz"
    graph.save(path)
    return path
