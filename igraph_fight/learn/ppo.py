"""The one PPO / GAE helper, shared by every trainer (igraph_fight.learn.train_rl, the tracker's
PPO route and the physics RL baseline).

    adv, ret = gae(rewards, values, next_values, continues, gamma=0.99, lam=0.95)
    loss = clipped_policy_loss(ratio, normalise(adv_batch), clip=0.2)

Arrays are time-major, (T,) or (T, N) numpy; ``next_values[t]`` is the value of the state after
step t, already 0 after a termination (a cut episode bootstraps with the value of its last
state); ``continues[t]`` is 0 where a trajectory ends at step t (terminated or cut), else 1.
``gamma`` is a scalar or a (T,) array of per-step discounts (decisions of different lengths).
The computation keeps the dtype of ``rewards``.
"""
from __future__ import annotations

import numpy as np


def gae(rewards: np.ndarray, values: np.ndarray, next_values: np.ndarray, continues: np.ndarray,
        gamma, lam: float) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimates and returns (advantages + values).

    delta_t = r_t + gamma_t * next_value_t - value_t;  A_t = delta_t + gamma_t * lam * continue_t * A_{t+1}.
    """
    rewards = np.asarray(rewards)
    T = rewards.shape[0]
    for name, a in (("values", values), ("next_values", next_values), ("continues", continues)):
        if np.shape(a) != rewards.shape:
            raise ValueError(f"gae: {name} has shape {np.shape(a)}, rewards {rewards.shape}")
    per_step = np.ndim(gamma) > 0
    if per_step and np.shape(gamma) != (T,):
        raise ValueError(f"gae: gamma has shape {np.shape(gamma)}, expected a scalar or ({T},)")
    adv = np.zeros_like(rewards)
    g = np.zeros_like(rewards[0]) if T else None
    for t in range(T - 1, -1, -1):
        gt = gamma[t] if per_step else gamma
        delta = rewards[t] + gt * next_values[t] - values[t]
        g = delta + gt * lam * continues[t] * g
        adv[t] = g
    return adv, adv + values


def normalise(adv):
    """Advantages standardised over a batch (numpy array or torch tensor)."""
    return (adv - adv.mean()) / (adv.std() + 1e-8)


def clipped_policy_loss(ratio, adv, clip: float):
    """PPO's clipped surrogate loss (torch tensors): -mean(min(ratio * A, clamp(ratio, 1 +- clip) * A))."""
    return -(ratio * adv).minimum(ratio.clamp(1.0 - clip, 1.0 + clip) * adv).mean()
