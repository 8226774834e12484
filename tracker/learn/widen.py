"""Widen a trained policy's observation to more reference horizons, keeping what it computes.

The policy's input (tracker.track.env.TrackingEnv.observe, then tracker.track.policy_net.balance_features) is laid
out as ``[proprioception (P)] [one block per horizon in obs_future (S numbers each)] [balance
features (B, when balance_obs)]``, with S = n_act + 8 (joint targets minus joints, root offset,
heading sin / cos, reference up vector). To continue a trained run with a longer look-ahead (say
(1, 2, 4) -> (1, 2, 4, 8, 12, 16)) without starting over:

- the first layer's weights of the new inputs are zero (the widened network computes exactly the
  old function until training moves them); the old inputs keep their weights;
- the observation normaliser's statistics of a new horizon's block are copied from the old
  block with the nearest horizon (a start, the running statistics take over);
- stored labels (observations without the new horizons) get the copied mean in the new columns,
  i.e. a normalised 0: they teach the old behaviour with the new inputs "at their mean".
  Approximation: those labels say nothing about the new inputs; new labels do.
"""
from __future__ import annotations

import numpy as np
import torch

from tracker.track.policy_net import N_BALANCE

#: Numbers per reference horizon in TrackingEnv.observe, besides the joint targets.
BLOCK_EXTRA = 8


def column_map(obs_dim_old: int, n_act: int, old_future: tuple[int, ...], new_future: tuple[int, ...],
               balance_obs: bool) -> tuple[np.ndarray, np.ndarray]:
    """(source, is_new) per column of the new observation: ``source`` is the old column it comes
    from (for a new column: the old column whose statistics it borrows), ``is_new`` marks columns
    with no old counterpart. Every old horizon must stay in ``new_future``."""
    missing = [h for h in old_future if h not in new_future]
    if missing:
        raise ValueError(f"obs_future {tuple(new_future)} drops the trained horizons {missing}; "
                         f"only adding horizons to {tuple(old_future)} is supported")
    s = n_act + BLOCK_EXTRA
    bal = N_BALANCE if balance_obs else 0
    p = obs_dim_old - len(old_future) * s - bal
    if p <= 0:
        raise ValueError(f"a {obs_dim_old}-number observation cannot hold {len(old_future)} horizons of {s}")
    src, new = list(range(p)), [False] * p
    for h in new_future:
        if h in old_future:
            j, fresh = old_future.index(h), False
        else:
            j, fresh = int(np.argmin([abs(h - g) for g in old_future])), True
        src.extend(range(p + j * s, p + (j + 1) * s))
        new.extend([fresh] * s)
    src.extend(range(obs_dim_old - bal, obs_dim_old))
    new.extend([False] * bal)
    return np.array(src), np.array(new)


def widen_checkpoint(ck: dict, new_future: tuple[int, ...]) -> tuple[dict, np.ndarray, np.ndarray]:
    """A copy of checkpoint ``ck`` whose policy (and critic, normaliser) read ``new_future``, and
    the column map used (``column_map``'s source and is_new, for ``widen_labels``). The
    optimisers' states are dropped (their shapes change); everything else is kept."""
    cfg = dict(ck["config"])
    old_future = tuple(cfg.get("obs_future", (1, 2, 4)))
    w0 = ck["policy"]["mu.0.weight"]
    n_act = int(ck["policy"]["log_std"].shape[0])
    if cfg.get("action_space", "joints") != "joints":
        raise ValueError("widening needs a joint-residual policy (action_space=joints)")
    src, new = column_map(int(w0.shape[1]), n_act, old_future, tuple(new_future), bool(cfg.get("balance_obs", True)))
    out = dict(ck)
    out["policy"] = dict(ck["policy"])
    out["policy"]["mu.0.weight"] = _widen_weight(w0, src, new)
    if "value" in ck:
        out["value"] = dict(ck["value"])
        first = sorted(k for k in ck["value"] if k.endswith(".weight"))[0]
        out["value"][first] = _widen_weight(ck["value"][first], src, new)
    out["obs_mean"] = np.asarray(ck["obs_mean"], float)[src]
    out["obs_var"] = np.asarray(ck["obs_var"], float)[src]
    for key in ("optimizer", "actor_optimizer"):
        out.pop(key, None)
    out["config"] = {**cfg, "obs_future": tuple(new_future)}
    return out, src, new


def widen_labels(obs: np.ndarray, src: np.ndarray, new: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Stored label observations (N, old dim) -> (N, new dim); new columns hold ``mean`` (new layout)."""
    out = obs[:, src].copy()
    out[:, new] = mean[new].astype(out.dtype)
    return out


def _widen_weight(w: torch.Tensor, src: np.ndarray, new: np.ndarray) -> torch.Tensor:
    out = w[:, torch.as_tensor(src)].clone()
    out[:, torch.as_tensor(new)] = 0.0
    return out
