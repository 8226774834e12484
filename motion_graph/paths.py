"""Where the mocap lives: --mocap option, IGRAPH_FIGHT_MOCAP, ../shared/mocap, or the user cache."""
from __future__ import annotations

import os
from pathlib import Path

ENV_VAR = "IGRAPH_FIGHT_MOCAP"


def user_cache_dir() -> Path:
    """Per-user cache folder (XDG_CACHE_HOME or ~/.cache)/igraph-fight."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "igraph-fight"


def default_fetch_dir() -> Path:
    """Where `igraph-fight data fetch-cmu` puts the CMU takes by default."""
    return user_cache_dir() / "mocap"


def candidate_mocap_roots() -> list[Path]:
    repo = Path(__file__).resolve().parent.parent
    return [Path.cwd().parent / "shared" / "mocap", repo.parent / "shared" / "mocap", default_fetch_dir()]


def find_mocap_root(explicit: str | os.PathLike | None = None) -> Path | None:
    """The mocap folder to use: explicit > $IGRAPH_FIGHT_MOCAP > ../shared/mocap > user cache; None if none exists."""
    if explicit:
        return Path(explicit)
    env = os.environ.get(ENV_VAR)
    if env:
        return Path(env)
    for c in candidate_mocap_roots():
        if c.is_dir():
            return c
    return None


def boxing_takes(root: Path) -> list[Path]:
    """The shared boxing takes under a mocap root, in library order: CMU subject 13's 13_17 and
    13_18 (BVH in cmu/boxing, else AMC anywhere), then subject 14's 14_02 where present (BVH or
    AMC anywhere; another skeleton, retargeted onto 13_17's body by default_boxing_library)."""
    takes: list[Path] = []
    for sub in ("cmu/boxing", "."):
        bvh = sorted((root / sub).glob("13_1[78].bvh"))
        if bvh:
            takes = bvh
            break
    if not takes:
        takes = sorted(root.rglob("13_1[78].amc"))
    if not takes:
        return []
    extra = sorted(root.rglob("14_02.bvh")) or sorted(root.rglob("14_02.amc"))
    return takes + extra[:1]


def boxing_files(mocap: str | os.PathLike | None) -> list[Path]:
    """The default boxing takes of the mocap folder (find_mocap_root(mocap)), or a MocapFormatError
    saying where to get them."""
    from motion_graph.errors import MocapFormatError

    root = find_mocap_root(mocap)
    if root is None or not root.is_dir():
        raise MocapFormatError(str(root or "../shared/mocap"),
                               f"no mocap folder; pass files, --mocap DIR, set {ENV_VAR}, "
                               f"or run `igraph-fight data fetch-cmu`")
    files = boxing_takes(root)
    if not files:
        raise MocapFormatError(str(root), "no CMU boxing takes (13_17, 13_18; 14_02 optional) in this folder")
    return files
