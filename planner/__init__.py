"""planner: rewards, styles and search (min-max, dynamic programming, roulette) on an Interaction
Graph given as plain arrays (docs/contracts.md). A leaf package: numpy and numba only.

Typical use (graph = dict of the contract arrays, kinds_table included)::

    sg = SearchGraph.from_arrays(graph["state_offsets"], graph["edge_target"], graph["edge_swap"])
    pol = compute_policy(graph, "outboxer", depth=5, search_graph=sg)     # on a style swap
    e = pol.best_me[s]                                                   # deterministic
    e = pol.select(s, graph["state_offsets"], graph["edge_target"], graph["edge_swap"], rng,
                   temperature=0.5, usage=counts, penalty=0.3)           # roulette
"""
from planner.dp import dp_packed, value_iteration, value_iteration_pair
from planner.minmax import balanced_chunks, minmax, minmax_packed, pack_keys, pack_weights
from planner.policy import DEFAULT_GAMMA, Policy, compute_policy
from planner.rewards import (
    COOP_FEATURES, FIGHT_FEATURES, N_DIRECTIONS, cooperative_rewards, direction_vector, edge_rewards,
    kind_preferences)
from planner.search_graph import ORDERINGS, SearchGraph
from planner.select import MODES, edge_scores, roulette_pick, roulette_probabilities, roulette_select, select_edge
from planner.styles import ATTACK_KINDS, Style, StyleError, list_presets, load_style, save_style, style_from_dict
from planner.synthetic_graph import random_features, synthetic_graph

__all__ = [
    "DEFAULT_GAMMA",
    "ATTACK_KINDS", "COOP_FEATURES", "FIGHT_FEATURES", "MODES", "N_DIRECTIONS", "ORDERINGS",
    "Policy", "SearchGraph", "Style", "StyleError",
    "balanced_chunks", "compute_policy", "cooperative_rewards", "direction_vector", "dp_packed",
    "edge_rewards", "edge_scores", "kind_preferences", "list_presets", "load_style", "minmax",
    "minmax_packed", "pack_keys", "pack_weights", "random_features", "roulette_pick",
    "roulette_probabilities", "roulette_select", "save_style", "select_edge", "style_from_dict",
    "synthetic_graph", "value_iteration", "value_iteration_pair",
]
