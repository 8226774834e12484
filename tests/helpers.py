"""Helpers shared by several test files (import them with ``from helpers import ...``; pytest puts
tests/ on sys.path)."""
from __future__ import annotations

import numpy as np
import pytest


def facing_start(setup, a_first: int, distance: float = 1.2):
    """A physics bout's initial FightState (setup: a tracker.bouts.setup.BoutSetup): fighter A at
    the origin facing B (heading 0 faces +Z), B facing A, both at the last frame of a guard action
    from which A's action ``a_first`` is legal."""
    lib = setup.library
    guards = [g for g in range(lib.n_actions) if a_first in set(int(x) for x in lib.next(g))]
    if not guards:
        pytest.skip("no action leads to the punch")
    g = guards[0]
    return setup.game.initial_state((0.0, 0.0), (0.0, distance), (0.0, np.pi), (g, int(setup.game.start_actions[0])))


def walk_qpos(setup, ctrl, walk, steps=24):
    """Track ``walk`` with ``ctrl`` in the evaluation setup's env for up to ``steps`` control steps:
    (qpos per step, the env's step counter, its simulated clock)."""
    from tracker.track.evaluation import walk_reference
    env = setup.env
    _, ref = walk_reference(setup, walk)
    obs = env.reset(ref, 0)
    ctrl.reset(env)
    out = []
    for _ in range(steps):
        obs, _, done, _ = env.step(ctrl.act(env, obs))
        out.append(env.data.qpos.copy())
        if done:
            break
    return np.array(out), env.t, env.sim_time
