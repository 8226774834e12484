"""A Gymnasium vector environment over the batched tracking env, so any RL library can train an
assisted tracker (gymnasium.vector conventions: batched arrays, terminations and truncations
apart, autoreset on the next step).

    env = TrackingVectorEnv(num_envs=16, cap=0.5, seed=0)     # pip install gymnasium
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())

Actions: (num_envs, n_act + 6) in [-1, 1]: PD-target residuals scaled by ``residual_scale`` rad,
then the assist wrench in cap units (facing frame). Episodes: a random walk of ``walk_actions``
actions from a random frame (reference-state initialisation), terminated by a fall, truncated at
``max_episode_steps`` or the walk's end. Reward: the env's (tracking terms scaled down by the assist).
"""
from __future__ import annotations

import numpy as np


def _gym():
    try:
        import gymnasium
    except ModuleNotFoundError:
        raise ModuleNotFoundError("TrackingVectorEnv needs gymnasium: pip install 'igraph-fight[gym]'") from None
    return gymnasium


class TrackingVectorEnv:
    """See the module docstring (a gymnasium.vector.VectorEnv)."""

    metadata = {"autoreset_mode": "NextStep"}

    def __new__(cls, *args, **kwargs):
        gym = _gym()
        if not issubclass(cls, gym.vector.VectorEnv):          # mix the base in at first use
            cls = type(cls.__name__, (cls, gym.vector.VectorEnv), {})
        return object.__new__(cls)

    def __init__(self, num_envs: int = 16, cap: float = 0.5, seed: int = 0, library=None, walk_actions: int = 10,
                 max_episode_steps: int = 300, residual_scale: float = 0.5, physics_hz: float = 120.0) -> None:
        gym = _gym()
        from tracker.track.assist import AssistConfig
        from tracker.track.batch_env import BatchConfig, BatchEnv
        from tracker.track.evaluation import make_setup
        from tracker.track.pd import STANCE_GAINS, PDTracker, batched_model_options
        from tracker.track.walks import LibraryWalks, default_library
        self.num_envs = int(num_envs)
        self._rng = np.random.default_rng(seed)
        self._src = LibraryWalks(library if library is not None else default_library(None))
        self._setup = make_setup(self._src, batched_model_options(physics_hz))
        self.env = BatchEnv(self._setup.scene, self.num_envs, BatchConfig(assist=AssistConfig("learned", cap)))
        PDTracker(class_scale=STANCE_GAINS).reset(self.env)
        self.walk_actions = walk_actions
        self.max_episode_steps = max_episode_steps
        self.residual_scale = residual_scale
        self._steps = np.zeros(self.num_envs, dtype=np.int64)
        self._ended = np.zeros(self.num_envs, dtype=bool)
        n_act = self.env.n_act + 6
        obs_dim = self.env.obs_dim
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (obs_dim,), np.float64)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (n_act,), np.float64)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (self.num_envs, obs_dim), np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.num_envs, n_act), np.float64)

    def _start(self, slots) -> None:
        from tracker.track.evaluation import walk_reference
        for b in slots:
            ref = walk_reference(self._setup, self._src.random_walk(self.walk_actions, self._rng), lift="ground")[1]
            s = int(self._rng.integers(0, max(1, ref.n_frames - 31)))
            self.env.reset([int(b)], [ref], [s], self._rng)
            self._steps[b] = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        self._start(range(self.num_envs))
        self._ended[:] = False
        return self.env.observe(), {}

    def step(self, actions):
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.num_envs, -1), -1.0, 1.0)
        if self._ended.any():                    # autoreset (NextStep): the ended slots start over first
            self._start(np.nonzero(self._ended)[0])
            self._ended[:] = False
        targets = self.env.reference_targets() + self.residual_scale * a[:, :self.env.n_act]
        obs, reward, done, info = self.env.step(targets, a[:, self.env.n_act:])
        self._steps += 1
        terminated = info["fall"] != 0
        truncated = (done & ~terminated) | (self._steps >= self.max_episode_steps)
        self._ended = terminated | truncated
        return obs, reward.astype(np.float64), terminated, truncated, {"mpjpe_m": info["mpjpe_m"],
                                                                     "assist_force_mg": self.env.assist_force_mg.copy()}

    def close_extras(self, **kwargs) -> None:
        pass
