"""The PPO learner's critic warm-up (TrainConfig.critic_warmup): fine-tuning a distilled policy
starts with updates that fit the critic only, then the actor moves too."""
from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")


def _batch(rng: np.random.Generator, E: int = 4, T: int = 16, D: int = 8, A: int = 3) -> dict:
    f = lambda *s: rng.standard_normal(s).astype(np.float32)  # noqa: E731
    term = (rng.random((E, T)) < 0.05).astype(np.float32)
    return {"obs": f(E, T, D), "act": f(E, T, A), "logp": f(E, T) - 3.0, "rew": rng.random((E, T)).astype(np.float32),
            "term": term, "trunc": np.zeros((E, T), np.float32), "trunc_obs": f(E, T, D), "last_obs": f(E, D)}


def _params(module) -> list[np.ndarray]:
    return [p.detach().numpy().copy() for p in module.parameters()]


def test_critic_warmup_keeps_the_actor_then_releases_it():
    from tracker.learn.train_tracker import Learner, TrainConfig
    cfg = TrainConfig(critic_warmup=2, hidden=(16, 16), critic_hidden=(16, 16), minibatch=32, epochs=2,
                      lr_actor=1e-2, target_kl=1e3)
    rng = np.random.default_rng(0)
    lrn = Learner(cfg, 8, 3, "cpu")
    lrn.norm.update(rng.standard_normal((64, 8)))
    actor0, critic0 = _params(lrn.actor), _params(lrn.critic)
    for _ in range(2):
        lrn.update(_batch(rng))
    assert all(np.array_equal(a, b) for a, b in zip(actor0, _params(lrn.actor)))
    assert not all(np.array_equal(a, b) for a, b in zip(critic0, _params(lrn.critic)))
    assert lrn.lr_actor == cfg.lr_actor                   # the step size is not adapted while warming up
    lrn.update(_batch(rng))
    assert not all(np.array_equal(a, b) for a, b in zip(actor0, _params(lrn.actor)))
