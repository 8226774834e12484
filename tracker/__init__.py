"""tracker: MuJoCo humanoids generated from the mocap skeleton track action-graph walks, and fight
physics bouts driven by the Interaction Graph.

    spec = fighter_spec(skeleton, motions)                 # calibrate a fighter on its mocap
    scene = build_fighter_scene(spec, n_fighters=1)        # MJCF ring scene, BodyMap per fighter
    ref = build_reference(motion, scene)                   # Motion -> qpos/qvel/PD targets
    env = TrackingEnv(scene); obs = env.reset(ref)         # control at 30 Hz, physics 240 Hz
    obs, reward, done, info = env.step(PDController().act(env, obs))
    metrics = evaluate_walks(make_setup(LibraryWalks(lib)), PDController())
    policy = load_default_policy()                         # the learned tracker (tracker/track/policy_net.py)
    balanced = PDController.balanced()                     # PD + virtual-force balance (tracker/track/vforce.py)
    metrics = evaluate_walks(make_setup(LibraryWalks(lib)), policy)

Packages by role: tracker.body (the fighter's model, contacts, falls, frames), tracker.track
(references, the tracking environment, controllers, the walk evaluation), tracker.bouts (physics
bouts, their agents and results), tracker.learn (trainers). The fall definition lives in
tracker.body.fall; the measurements behind the design in docs/tracker.md.
"""
import importlib

_EXPORTS = {
    "body.fighter_contacts": ("FighterContact", "fighter_contacts"),
    "track.controllers": ("CONTROLLERS", "Controller", "make_controller"),
    "track.env": ("EnvConfig", "StepInfo", "TrackingEnv"),
    "track.evaluation": ("EvalSetup", "WalkResult", "draw_walks", "evaluate_walks", "format_report", "make_setup",
                         "run_walk"),
    "body.fall": ("PELVIS_DROP_M", "FallConfig", "detect_fall"),
    "body.humanoid": ("C_MOCAP_TO_MJ", "EFFECTOR_LABELS", "TARGET_LABELS", "BodyMap", "FighterScene", "ModelOptions",
                      "build_fighter_scene"),
    "track.pd": ("PDController",),
    "track.policy_net": ("LearnedController", "load_default_policy", "load_policy"),
    "track.reference": ("FootPenetration", "Reference", "build_reference", "kinematic_error", "placement_transform"),
    "body.spec": ("FighterSpec", "FootCalibration", "fighter_spec"),
    "track.vforce": ("BalanceGains", "VirtualForceBalance"),
    "track.walks": ("ClipWindows", "LibraryWalks", "default_library", "walk_source"),
}
_WHERE = {name: mod for mod, names in _EXPORTS.items() for name in names}


def __getattr__(name: str):
    """Public names are imported on first use, so `import tracker.cli` (done by every igraph-fight
    command) does not load MuJoCo."""
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module 'tracker' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{mod}", __name__), name)
    globals()[name] = value
    return value


__all__ = sorted(_WHERE)
