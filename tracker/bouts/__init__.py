"""Physics bouts: two tracked humanoids in one ring, each driven by an action-choosing agent.

setup (rules, shared scene, per-fighter state), physics_bout (PhysicsBout), judging (hits from
contacts), results (PhysicsBoutResult), agents (DecisionContext, scripted and closing agents),
loaders (tracking controller and agent from a name), rl_agent / rl_eval (the physics RL baseline),
hit_model (the physically measured hit odds and their IG fighter), run (a bout to its artifacts,
series), media (log, plots, video), cli (the `igraph-fight tracker bouts|rl|hit-model` commands).
"""
