"""motion_graph: real mocap -> actions -> the action-level motion graph Next(a).

Conventions: metres, Y up, heading about +Y (0 faces +Z, +X is left), quaternions (x, y, z, w).
"""
from motion_graph.classify import ATTACK_KINDS, DEFENCE_KINDS, KINDS, MOVE_KINDS
from motion_graph.errors import LibraryFormatError, MocapFormatError
from motion_graph.io import find_mocap_files, load_motion
from motion_graph.io_asfamc import load_asf, load_asf_amc
from motion_graph.io_bvh import load_bvh, save_bvh
from motion_graph.library import ActionLibrary, LibraryParams, build_library, load_library, segment_files
from motion_graph.motion import Motion, forward_kinematics
from motion_graph.paths import find_mocap_root
from motion_graph.semantics import resolve_parts
from motion_graph.skeleton import Skeleton

__all__ = [
    "ATTACK_KINDS", "DEFENCE_KINDS", "KINDS", "MOVE_KINDS", "LibraryFormatError", "MocapFormatError",
    "find_mocap_files", "load_motion", "load_asf", "load_asf_amc", "load_bvh", "save_bvh", "ActionLibrary",
    "LibraryParams", "build_library", "load_library", "segment_files", "Motion", "forward_kinematics",
    "find_mocap_root", "resolve_parts", "Skeleton",
]
