"""Load any supported mocap file or folder into Motion objects."""
from __future__ import annotations

import os
from pathlib import Path

from motion_graph.errors import MocapFormatError, check_rate, check_scale
from motion_graph.io_asfamc import CMU_FPS, find_asf_for, load_amc, load_asf
from motion_graph.io_bvh import load_bvh
from motion_graph.motion import Motion

MOCAP_SUFFIXES = (".bvh", ".amc")


def load_motion(path: str | os.PathLike, fps: float | None = None, metres_per_unit: float | None = None) -> Motion:
    """Load a .bvh file, or an .amc file with the .asf beside it.

    Args:
        fps: override the frame rate (BVH header / CMU's 120 fps for AMC); it must be finite and
            within motion_graph.errors.MIN_FPS..MAX_FPS (0.1..10,000).
        metres_per_unit: override the length unit (finite, positive).
    Raises:
        MocapFormatError: every problem with the file, and a bad fps or metres_per_unit (the
            error names the file; MocapFormatError is a ValueError).
    """
    p = Path(path)
    if fps is not None:
        check_rate(str(p), fps)
    if metres_per_unit is not None:
        check_scale(str(p), metres_per_unit)
    if not p.exists():
        raise MocapFormatError(str(p), "no such file")
    suf = p.suffix.lower()
    if suf == ".bvh":
        return load_bvh(p, fps=fps, metres_per_unit=metres_per_unit)
    if suf == ".amc":
        return load_amc(p, load_asf(find_asf_for(p), metres_per_unit), CMU_FPS if fps is None else fps)
    raise MocapFormatError(str(p), f"unsupported file type {suf!r} (expected .bvh or .amc)")


def find_mocap_files(paths: list[str | os.PathLike], recursive: bool = True) -> list[Path]:
    """Expand files and folders into a sorted list of .bvh / .amc files.

    In a folder holding both X.bvh and an .amc of the same stem, the BVH is taken once.
    """
    out: list[Path] = []
    for item in paths:
        p = Path(item)
        if p.is_dir():
            found = [f for f in (p.rglob("*") if recursive else p.glob("*"))
                     if f.is_file() and f.suffix.lower() in MOCAP_SUFFIXES]
            out.extend(sorted(found))
        elif p.exists():
            out.append(p)
        else:
            raise MocapFormatError(str(p), "no such file or folder")
    seen_bvh = {f.stem for f in out if f.suffix.lower() == ".bvh"}
    uniq: list[Path] = []
    for f in out:
        if f.suffix.lower() == ".amc" and f.stem in seen_bvh:
            continue
        if f not in uniq:
            uniq.append(f)
    return uniq
