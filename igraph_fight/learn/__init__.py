"""Learning shared by the RL baselines and the tracker's trainers: the one PPO/GAE helper (``ppo``)
and the kinematic RL baseline's training route (``train_rl``). torch is imported only by what needs it."""
