"""Training: the tracking policy (train_tracker: PPO and policy-guided search with distillation,
search_labels, widen), the physics RL baseline (train_physics_rl) and the hit model
(train_hit_model); ``--set KEY=VALUE`` overrides of their configs (overrides)."""
