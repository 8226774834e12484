"""The two-fighter world of a physics bout on the batched environment (one world, two fighter
slots): the calls PhysicsBout makes of its environment, answered by tracker.track.batch_env.BatchEnv.

The bout writes each fighter's reference online (a buffer over the bout's control steps) and the
per-frame tables the batched observation reads (``batch_tables_k`` in the reference's meta), so
the environment never terminates an episode: falls are the bout's to handle (pause, get up).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker.track.batch_env import FALL_NAMES, BatchConfig, BatchEnv


@dataclass
class StepInfo:
    """What the bout reads after a step: per fighter the fall reason (None: standing) and the joint error (m)."""

    t: int
    fall: list[str | None]
    mpjpe_m: list[float]


@dataclass
class FighterAddress:
    """The addresses of one fighter the bout reads (pelvis body, hip line, qvel slice)."""

    pelvis: int
    lateral: np.ndarray
    qvel: slice


class BoutEnv:
    """A BatchEnv of one two-fighter world seen through the calls of PhysicsBout."""

    batched = True
    residual_actions = False

    def __init__(self, scene, config: BatchConfig) -> None:
        from dataclasses import replace
        self.batch = BatchEnv(scene, 1, replace(config, terminate_on_fall=False))
        self.scene = scene
        self.model = scene.model
        self.config = self.batch.config
        self.n_fighters = self.batch.F
        self._cache = [FighterAddress(L.pelvis, L.lateral, slice(int(L.qvel[0]), int(L.qvel[-1]) + 1))
                       for L in self.batch.layouts]
        self._hook = None

    # what PhysicsBout reads ------------------------------------------------------------------
    @property
    def data(self):
        return self.batch.datas[0]

    @property
    def t(self) -> int:
        return int(self.batch.t[0])

    @property
    def t_end(self) -> int:
        return int(self.batch.t_end[0])

    @property
    def refs(self) -> list:
        return self.batch.refs

    @property
    def n_act(self) -> int:
        return self.batch.n_act * self.batch.F

    @property
    def substep_hook(self):
        return self._hook

    @substep_hook.setter
    def substep_hook(self, hook) -> None:
        self._hook = hook
        self.batch.substep_hook = None if hook is None else (lambda w, d, s: hook(d, s))

    def reset(self, refs: list, start_frame: int = 0):
        return self.batch.reset(np.arange(self.batch.F), list(refs), [start_frame] * self.batch.F)

    def reference_targets(self, lead: int | None = None) -> np.ndarray:
        """(2, n_act) reference PD targets of the coming step (what a batched controller reads)."""
        return self.batch.reference_targets(lead)

    def __getattr__(self, name: str):
        # gains, observations and the rest: the batched env's (controllers call them)
        if name == "batch":
            raise AttributeError(name)
        return getattr(self.batch, name)

    def step(self, act: np.ndarray, assist: np.ndarray | None = None):
        obs, rew, done, info = self.batch.step(np.asarray(act, dtype=np.float64).reshape(self.batch.F, -1), assist)
        si = StepInfo(self.t, [FALL_NAMES.get(int(c)) for c in info["fall"]], [float(x) for x in info["mpjpe_m"]])
        return obs, rew, done, si

    def _obs_all(self) -> np.ndarray:
        """The observation after the bout edited the world (a fighter reset: positions refreshed)."""
        self.batch.refresh()
        return self.batch.observe()

    def set_root_assist(self, on: bool) -> None:
        raise ValueError("the root weld is not available with the assisted tracker (it has its own bounded assist)")

    @property
    def realtime_factor(self) -> float:
        return self.batch.realtime_factor
