"""Extra initial states for the sampler, taken from reward-free bouts in the kinematic game.

The tree-expansion sampler starts from a spread of guard-vs-guard states and expands four or so
rounds before its archive is full, so the coupled states of a long bout (any action of the other
fighter at any frame, after many exchanges) are reached only by chance: on the CMU boxing graph
about half of the states a depth-3 game-tree fighter visits had no graph state within tolerance.
Seeding the archive with the decision states of a few bouts between two scripted human proxies
(``pairing="human"``, the default) or a human proxy and a random fighter (``"random"``) puts such
states at the roots of the tree. Neither agent uses a reward, so the archive still does not
depend on any reward. Bouts of two proxies cover the game-tree fighter's states better than
bouts of a proxy against a random fighter (86% against 72% on the CMU boxing graph, measured as
build.BuildOptions records).
"""
from __future__ import annotations

import numpy as np

from igraph_fight.sim import N_SF, N_SI, SimTables

SEED_PAIRINGS = ("human", "random")


def bout_seed_states(library, tables: SimTables, n_bouts: int, seconds: float, seed: int,
                     pairing: str = "human", backend=None) -> tuple[np.ndarray, np.ndarray]:
    """Canonical samples (si (N, N_SI), sf (N, N_SF)) of both fighters at every decision of
    ``n_bouts`` bouts of ``seconds`` between the human proxy and a second human proxy
    (``pairing="human"``) or a random fighter (``"random"``; slots alternate), started from the
    game's random initial states drawn from ``seed``. Bouts are independent (each has its own
    generator, drawn in order from ``seed``): ``backend`` (igraph_fight.build.backend) may play
    runs of them elsewhere; the rows come back in bout order either way."""
    if pairing not in SEED_PAIRINGS:
        raise ValueError(f"pairing must be one of {', '.join(SEED_PAIRINGS)}, not {pairing!r}")
    rng = np.random.default_rng(seed)
    seeds = np.array([rng.integers(1 << 62) for _ in range(int(n_bouts))], dtype=np.int64)
    if backend is None:
        parts = [seed_bout_range(library, tables, seconds, pairing, seeds, 0)]
    else:
        parts = backend.seed_bouts(library, seconds, pairing, seeds)
    parts = [p for p in parts if len(p[0])]
    if not parts:
        return np.zeros((0, N_SI), dtype=np.int64), np.zeros((0, N_SF), dtype=np.float64)
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def seed_bout_range(library, tables: SimTables, seconds: float, pairing: str, seeds: np.ndarray,
                    first: int) -> tuple[np.ndarray, np.ndarray]:
    """The decision samples of bouts first, first + 1, ... (bout first + j seeded by seeds[j])."""
    from igraph_fight.agents.base import RandomAgent
    from igraph_fight.agents.human import HumanProxyAgent
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.match import run_bout
    from igraph_fight.state import to_sample

    game = FightGame(library, GameConfig(max_seconds=seconds, sim=tables.params), tables=tables)
    si_rows: list[np.ndarray] = []
    sf_rows: list[np.ndarray] = []

    class _Recorder:
        def __init__(self, agent) -> None:
            self.agent = agent
            self.name = agent.name

        def reset(self, g, player: int, rng: np.random.Generator) -> None:
            self.agent.reset(g, player, rng)

        def step(self, state, player: int) -> int:
            si, sf = to_sample(state.game.tables, state.world, player)
            si_rows.append(np.asarray(si, dtype=np.int64))
            sf_rows.append(np.asarray(sf, dtype=np.float64))
            return self.agent.step(state, player)

    # one pair of agents for all bouts: run_bout resets them (generator, what they saw) each time
    fighters = [_Recorder(HumanProxyAgent()), _Recorder(HumanProxyAgent() if pairing == "human" else RandomAgent())]
    for j, s in enumerate(seeds):
        i = int(first) + j
        pair = fighters[::-1] if i % 2 else fighters
        run_bout(game, pair, seconds, np.random.default_rng(int(s)))
    if not si_rows:
        return np.zeros((0, N_SI), dtype=np.int64), np.zeros((0, N_SF), dtype=np.float64)
    return np.stack(si_rows), np.stack(sf_rows)
