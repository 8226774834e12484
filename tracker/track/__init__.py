"""Tracking: references built from action-graph walks (reference, walks), the tracking environment
(env) and its reward (tracking_reward), the controllers that track (controllers: the Controller
protocol and its registry; pd; the virtual-force balance layer vforce; the learned policy
policy_net), the walk evaluation protocol (evaluation) and pictures of it (render)."""
