"""The Gymnasium vector wrapper of the batched tracking env follows gymnasium.vector's conventions."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.realdata


def test_gymnasium_vector_env(boxing_library):
    gym = pytest.importorskip("gymnasium")
    from tracker.track.gym_env import TrackingVectorEnv
    env = TrackingVectorEnv(num_envs=3, cap=0.3, seed=0, library=boxing_library, walk_actions=2, max_episode_steps=12)
    assert isinstance(env, gym.vector.VectorEnv)
    obs, info = env.reset(seed=1)
    assert obs.shape == env.observation_space.shape and env.action_space.shape[0] == 3
    ended_seen = False
    for _ in range(14):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        assert obs.shape == (3, env.single_observation_space.shape[0]) and r.shape == (3,)
        assert term.dtype == bool and trunc.dtype == bool and np.isfinite(r).all()
        assert (info["assist_force_mg"] <= 0.3 + 1e-12).all()
        ended_seen |= bool((term | trunc).any())
    assert ended_seen                        # the step cap ends episodes, which then restart
