"""tracker: MuJoCo humanoids generated from the mocap skeleton track action-graph walks.

    spec = fighter_spec(skeleton, motions)                 # calibrate a fighter on its mocap
    scene = build_fighter_scene(spec, n_fighters=1)        # MJCF ring scene, BodyMap per fighter
    ref = build_reference(motion, scene)                   # Motion -> qpos/qvel/PD targets
    env = TrackingEnv(scene); obs = env.reset(ref)         # control at 30 Hz, physics 240 Hz
    obs, reward, done, info = env.step(PDController().act(env, obs))
    metrics = evaluate_walks(make_setup(LibraryWalks(lib)), PDController())
    policy = load_default_policy()                         # the learned tracker (tracker/policy.py)
    balanced = PDController.balanced()                     # PD + virtual-force balance (tracker/vforce.py)
    metrics = evaluate_walks(make_setup(LibraryWalks(lib)), policy)

The fall definition lives in tracker.fall; measurements behind the design in tracker/MEASUREMENTS.md,
the learned tracker's routes and their figures in tracker/TRAINING.md.
"""
import importlib

_EXPORTS = {
    "contacts": ("FighterContact", "fighter_contacts"),
    "controller": ("CONTROLLERS", "Controller", "make_controller", "register_controller"),
    "env": ("EnvConfig", "StepInfo", "TrackingEnv"),
    "evaluate": ("EvalSetup", "WalkResult", "draw_walks", "evaluate_walks", "format_report", "make_setup", "run_walk"),
    "fall": ("PELVIS_DROP_M", "FallConfig", "detect_fall"),
    "model": ("C_MOCAP_TO_MJ", "EFFECTOR_LABELS", "TARGET_LABELS", "BodyMap", "FighterScene", "ModelOptions",
              "build_fighter_scene"),
    "pd": ("PDController",),
    "policy": ("LearnedController", "load_default_policy", "load_policy"),
    "reference": ("FootPenetration", "Reference", "build_reference", "kinematic_error", "placement_transform"),
    "spec": ("FighterSpec", "FootCalibration", "fighter_spec"),
    "vforce": ("BalanceGains", "VirtualForceBalance"),
    "walks": ("ClipWindows", "LibraryWalks", "default_library", "walk_source"),
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


__all__ = [
    "FighterContact", "fighter_contacts", "CONTROLLERS", "Controller", "make_controller", "register_controller",
    "EnvConfig", "StepInfo", "TrackingEnv", "EvalSetup", "WalkResult", "draw_walks", "evaluate_walks",
    "format_report", "make_setup", "run_walk", "PELVIS_DROP_M", "FallConfig", "detect_fall", "C_MOCAP_TO_MJ",
    "EFFECTOR_LABELS", "TARGET_LABELS", "BodyMap", "FighterScene", "ModelOptions", "build_fighter_scene",
    "PDController", "LearnedController", "load_default_policy", "load_policy", "FootPenetration", "Reference", "build_reference", "kinematic_error", "placement_transform",
    "FighterSpec", "FootCalibration", "fighter_spec", "ClipWindows", "LibraryWalks", "default_library",
    "walk_source", "BalanceGains", "VirtualForceBalance",
]
