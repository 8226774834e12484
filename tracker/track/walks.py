"""Where reference motions come from: random walks through the action graph (ActionLibrary), or
windows of raw clips when no library is at hand. A small adapter keeps the tracker independent
of how the library is stored.

A walk source has ``skeleton``, ``fps``, ``random_walk(n_actions, rng) -> list[int]`` and
``sequence_motion(ids, blend_frames) -> Motion`` (world coordinates, library fps), plus
``calibration_motions() -> list[Motion]`` (the frames the fighter model is calibrated on).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from motion_graph.motion import Motion
from motion_graph.skeleton import Skeleton


class LibraryWalks:
    """Walks through an ActionLibrary (motion_graph.library)."""

    def __init__(self, library) -> None:
        self.library = library
        self.skeleton: Skeleton = library.skeleton
        self.fps: float = float(library.fps)

    @property
    def n_actions(self) -> int:
        return int(self.library.n_actions)

    def random_walk(self, n_actions: int, rng: np.random.Generator) -> list[int]:
        return [int(a) for a in self.library.random_walk(n_actions, rng)]

    def sequence_motion(self, ids: list[int], blend_frames: int = 4) -> Motion:
        return self.library.sequence_motion(list(ids), blend_frames=blend_frames)

    def calibration_motions(self) -> list[Motion]:
        """Every library frame as one Motion (actions in their start frames, floor at y = 0)."""
        lib = self.library
        return [Motion(lib.skeleton, lib.rotations, lib.root_positions, lib.fps, lib.local_translations, "library")]

    def describe(self) -> str:
        return f"action library: {self.n_actions} actions at {self.fps:g} fps"


@dataclass
class ClipWindows:
    """Stand-in walk source: a "walk" of n actions is a window of n * action_s seconds of a clip.

    Attributes:
        motions: clips of one skeleton (resampled to ``fps``).
        action_s: seconds per pseudo-action.
    """

    motions: list[Motion]
    fps: float = 30.0
    action_s: float = 1.0

    def __post_init__(self) -> None:
        self.motions = [m.resample(self.fps) for m in self.motions]
        self.skeleton = self.motions[0].skeleton

    @property
    def n_actions(self) -> int:
        return int(sum(m.duration // self.action_s for m in self.motions))

    def random_walk(self, n_actions: int, rng: np.random.Generator) -> list[int]:
        """[clip, start frame, n frames] encoded as a 3-list (not action ids)."""
        n = max(2, int(round(n_actions * self.action_s * self.fps)) + 1)
        ok = [i for i, m in enumerate(self.motions) if m.n_frames >= n] or [int(np.argmax([m.n_frames for m in self.motions]))]
        i = int(rng.choice(ok))
        n = min(n, self.motions[i].n_frames)
        s = int(rng.integers(0, self.motions[i].n_frames - n + 1))
        return [i, s, n]

    def sequence_motion(self, ids: list[int], blend_frames: int = 4) -> Motion:
        i, s, n = ids
        return self.motions[i].slice(s, s + n)

    def calibration_motions(self) -> list[Motion]:
        return list(self.motions)

    def describe(self) -> str:
        return f"clip windows ({len(self.motions)} clips, {self.action_s:g} s per pseudo-action)"


def default_library(mocap_root: str | os.PathLike | None = None):
    """The default action library (motion_graph.retarget.default_boxing_library: the shared boxing
    takes on 13_17's body)."""
    from motion_graph.retarget import default_boxing_library
    return default_boxing_library(mocap_root)


def walk_source(library: str | os.PathLike | None = None, mocap_root: str | os.PathLike | None = None,
                clips: list[str | os.PathLike] | None = None):
    """A walk source: a saved library file, raw clips (windows), or the default boxing library."""
    if clips:
        from motion_graph.io import load_motion
        return ClipWindows([load_motion(c) for c in clips])
    if library:
        from motion_graph.library import load_library
        return LibraryWalks(load_library(library))
    return LibraryWalks(default_library(mocap_root))
