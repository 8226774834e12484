"""The tracker's plugin of the igraph-fight command (entry points in pyproject.toml):
``register(subparsers)`` adds the `igraph-fight tracker ...` group, ``physics_fight(args)`` runs
`igraph-fight fight --physics ...`.

    igraph-fight tracker eval [--controller pd|balance|learned] [--ckpt CKPT] --walks 100 --actions 20 --seed 0
                              [--workers N] [--json]
    igraph-fight tracker render --out walk.png|walk.mp4 [--actions 6] [--seed 0] [--seconds 6]
    igraph-fight tracker model FILE.bvh --out fighter.xml [--fighters 2]
    igraph-fight tracker train --library LIB --minutes M --out CKPT [--resume CKPT] [--device auto]
    igraph-fight tracker bouts fight|series ...       (physics bouts: tracker.bouts.cli)
    igraph-fight tracker rl train|eval ...            (the physics RL baseline)
    igraph-fight tracker hit-model collect|kinds|train ...

``--controller learned`` without ``--ckpt`` loads the shipped policy (tracker/checkpoints/boxing_cmu13.pt).

Walks come from ``--library LIB`` (a saved action library), else from the shared CMU boxing
takes (built on the fly with motion_graph), or from raw clip windows with ``--clips FILE ...``.
"""
from __future__ import annotations

import argparse
import json
import sys

from igraph_fight.cli import non_negative_int, positive_float, positive_int, probability


def register(subparsers) -> None:
    p = subparsers.add_parser("tracker", help="physics tracking of action-graph walks in MuJoCo",
                              description="Track action-graph walks with MuJoCo humanoids: evaluate "
                                          "controllers, render reference vs simulation, export the model.")
    sub = p.add_subparsers(dest="tracker_command", metavar="TRACKER_COMMAND")
    sub.required = True

    def source_args(q: argparse.ArgumentParser) -> None:
        q.add_argument("--library", help="action library file (default: the shared boxing takes 13_17, 13_18, 14_02 on one body)")
        q.add_argument("--mocap", help="mocap folder (default: $IGRAPH_FIGHT_MOCAP or ../shared/mocap)")
        q.add_argument("--clips", nargs="+", help="track windows of these clips instead of library walks")
        q.add_argument("--controller", default="pd", help="pd (default), balance (PD + virtual-force balance, "
                       "tracker/track/vforce.py) or learned (the learned policy, tracker/track/policy_net.py)")
        q.add_argument("--ckpt", help="controller checkpoint (learned policy, default the shipped "
                                      "tracker/checkpoints/boxing_cmu13.pt; for pd a JSON of gains)")
        q.add_argument("--physics-hz", type=positive_float, default=240.0, help="physics rate (default 240)")
        q.add_argument("--seed", type=non_negative_int, default=0, help="random seed of the walks (default 0)")
        q.add_argument("--actions", type=positive_int, default=20, help="actions per walk (default 20)")

    e = sub.add_parser("eval", help="random walks through the action graph, tracked; completion, time to fall, error",
                       description="The walk protocol (docs/protocols.md, Tracking). With --assist the batched "
                                   "environment at 120 Hz runs it: --assist learned is the assisted tracker with its own "
                                   "bounded wrench, --assist fixed PD with the fixed wrench, --assist none plain physics "
                                   "(--controller learned: the assisted tracker's policy with its wrench off). Without "
                                   "--assist the legacy tracking environment runs --controller pd|balance|learned.")
    source_args(e)
    e.add_argument("--assist", choices=("none", "fixed", "learned"), default=None,
                   help="the balance assist: none (physics), fixed (a PD wrench toward the reference root pose) or "
                        "learned (the assisted tracker's own); figures are labelled assisted physics (cap C mg)")
    e.add_argument("--cap", type=positive_float, default=None,
                   help="assist cap in body weights (force c*mg, torque c*mg*1 m); default 0.5 for fixed, the "
                        "policy's own for learned")
    e.add_argument("--parallel", type=positive_int, default=8, help="walks simulated side by side in one process "
                   "(batched env; default 8; the figures do not depend on it except the real-time factor)")
    e.add_argument("--placement", choices=("world", "body"), default="world",
                   help="world (default): track each walk as drawn, its root path fixed in the world; body: place "
                        "each action's clip under the simulated pelvis at its start, as a game and the physics bouts "
                        "do (with --assist only)")
    e.add_argument("--walks", type=positive_int, default=100, help="number of walks (default 100)")
    e.add_argument("--json", action="store_true", help="print the metrics as JSON")
    e.add_argument("--progress", action="store_true", help="show a progress bar")
    e.add_argument("--workers", type=positive_int, default=1, help="processes tracking walks in parallel (default 1; "
                   "the metrics equal a serial run's, the real-time factor is per process)")
    e.set_defaults(func=cmd_eval)

    r = sub.add_parser("render", help="side-by-side reference vs simulation: PNG contact sheet or MP4")
    source_args(r)
    r.set_defaults(actions=6)
    r.add_argument("--out", required=True, help="output .png (contact sheet) or .mp4 (video)")
    r.add_argument("--walk-index", type=non_negative_int, default=0, help="which walk of the seed (default 0: the first)")
    r.add_argument("--seconds", type=positive_float, default=6.0, help="seconds of motion to show (default 6)")
    r.add_argument("--frames", type=positive_int, default=8, help="contact sheet columns (default 8)")
    r.add_argument("--video-fps", type=positive_float, default=15.0, help="MP4 frame rate (default 15)")
    r.add_argument("--width", type=positive_int, default=400)
    r.add_argument("--height", type=positive_int, default=300)
    r.add_argument("--backend", choices=("egl", "osmesa"), help="OpenGL backend (default: EGL, else OSMesa)")
    r.set_defaults(func=cmd_render)

    t = sub.add_parser("train", help="train the learned tracking policy (PPO on action-graph walks, both cores)",
                       description="Train or continue (--resume) the learned tracking policy; writes a resumable "
                                   "checkpoint and a learning-curve PNG next to it.")
    add_train_arguments(t)
    t.set_defaults(func=cmd_train)

    ta = sub.add_parser("train-assisted", help="train the assisted tracker (PPO on the batched env, one core)",
                        description="Train or continue (--resume) the assisted tracker: one policy over the action "
                                    "library that outputs PD-target residuals and a bounded balance wrench, the cap "
                                    "lowered while the running completion stays high. Writes a resumable checkpoint "
                                    "and a learning-curve PNG next to it.")
    ta.add_argument("--library", help="action library file (default: the shared boxing takes 13_17, 13_18, 14_02 on one body)")
    ta.add_argument("--minutes", type=float, required=True, help="wall-clock minutes to train (this run)")
    ta.add_argument("--out", required=True, help="checkpoint to write (.pt), atomically, every few minutes and at the end")
    ta.add_argument("--resume", help="continue from this checkpoint (its config, optimiser, curriculum and budget)")
    ta.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="override an AssistedTrainConfig field (repeatable; on --resume it replaces the stored "
                         "value, cap_start restarts the cap curriculum there), e.g. --set n_envs=16")
    ta.add_argument("--no-progress", action="store_true", help="no progress bar")
    ta.set_defaults(func=cmd_train_assisted)

    tb = sub.add_parser("train-assisted-bouts", help="continue the assisted tracker inside physics bouts (PPO, one core)",
                        description="Continue an assisted-tracker checkpoint (default: the shipped one) inside "
                                    "physics bouts between planner fighters: the opponent, the planner's sequences "
                                    "and their placement are in the episodes, a fall ends a fighter's episode. "
                                    "Assisted physics at the checkpoint's cap. Writes a checkpoint of the same "
                                    "format (resumable by either route) and a learning-curve PNG next to it.")
    tb.add_argument("--graph", required=True, help="interaction graph file the planner fighters use")
    tb.add_argument("--minutes", type=float, required=True, help="wall-clock minutes to train (this run)")
    tb.add_argument("--out", required=True, help="checkpoint to write (.pt), atomically, every few minutes and at the end")
    tb.add_argument("--resume", help="checkpoint to continue (default: tracker/checkpoints/assisted_cmu13.pt)")
    tb.add_argument("--set", action="append", metavar="KEY=VALUE",
                    help="override a BoutTrainConfig field (styles, depth, bout_seconds, seed0, noise_seed) or an "
                         "AssistedTrainConfig field (PPO: lr, epochs, ...); repeatable")
    tb.add_argument("--no-progress", action="store_true", help="no progress bar")
    tb.set_defaults(func=cmd_train_assisted_bouts)

    gr = sub.add_parser("ground", help="the grounded reference: foot float and penetration before and after grounding",
                        description="Build the protocol's walk references and report the lower foot's height "
                                    "(as captured on the model, then grounded by tracker.track.grounding), the share "
                                    "of frames with both feet more than 1.5 cm up and the penetration.")
    source_args(gr)
    gr.add_argument("--walks", type=positive_int, default=20, help="number of walks (default 20)")
    gr.add_argument("--json", action="store_true", help="print the statistics as JSON")
    gr.set_defaults(func=cmd_ground)

    m = sub.add_parser("model", help="write the generated MJCF of a skeleton (calibrated on the file's motion)")
    m.add_argument("file", help=".bvh or .amc file")
    m.add_argument("--out", required=True, help="output .xml")
    m.add_argument("--fighters", type=int, default=1, choices=(1, 2))
    m.add_argument("--physics-hz", type=positive_float, default=240.0)
    m.set_defaults(func=cmd_model)

    from tracker.bouts.cli import add_bout_commands, add_hit_model_commands, add_rl_commands
    add_bout_commands(sub)
    add_rl_commands(sub)
    add_hit_model_commands(sub)


def add_train_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments of `tracker train` (here, not in tracker.learn.train_tracker, so the CLI starts without torch)."""
    p.add_argument("--library", help="action library file (default: the shared boxing takes 13_17, 13_18, 14_02 on one body)")
    p.add_argument("--minutes", type=positive_float, required=True, help="wall-clock minutes to train (this run)")
    p.add_argument("--out", required=True, help="checkpoint to write (.pt); a learning-curve .png goes next to it, and for "
                   "search runs the label buffer (CKPT.labels.npz, reloaded by --resume)")
    p.add_argument("--resume", help="continue from this checkpoint (its config is kept)")
    p.add_argument("--device", default="auto", help="auto (GPU when present, else CPU), cpu or cuda")
    p.add_argument("--workers", type=positive_int, default=2, help="environment processes (default 2: one per core)")
    p.add_argument("--envs", type=positive_int, default=16, help="environments per worker (default 16)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0)")
    p.add_argument("--push-prob", type=probability, help="per-step chance of a push, in [0, 1] (default: the config's)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a TrainConfig field (repeatable), e.g. --set lr_actor=1e-4 --set push_prob=0.01")
    p.add_argument("--slim", action="store_true", help="also write OUT-slim.pt: without the optimizer state (to ship)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def _setup(args):
    from tracker.track.evaluation import make_setup
    from tracker.body.humanoid import ModelOptions
    from tracker.track.walks import walk_source
    src = walk_source(args.library, args.mocap, args.clips)
    return make_setup(src, ModelOptions(physics_hz=args.physics_hz))


def _controller(args):
    """The controller of `tracker eval|render`: ``args.controller`` by name
    (tracker.track.controllers.make_controller with ``args.ckpt``), or the controller object a
    caller of cmd_eval / cmd_render put there."""
    if not isinstance(args.controller, str):
        return args.controller
    from tracker.track.controllers import make_controller
    return make_controller(args.controller, args.ckpt)


def cmd_eval(args) -> int:
    from tracker.track.evaluation import evaluate_walks, format_report
    if args.walks < 1 or args.actions < 1:
        print("igraph-fight: error: tracker eval: --walks and --actions must be >= 1", file=sys.stderr)
        return 2
    if getattr(args, "assist", None) is not None or args.controller == "assisted":
        return _eval_batched(args)
    if args.placement != "world":
        print("igraph-fight: error: tracker eval: --placement body needs --assist (the batched walk protocol)",
              file=sys.stderr)
        return 2
    try:
        controller = _controller(args)
    except (ValueError, FileNotFoundError) as e:
        print(f"igraph-fight: error: tracker eval: {e}", file=sys.stderr)
        return 2
    setup = _setup(args)
    metrics = evaluate_walks(setup, controller, args.walks, args.actions, args.seed, progress=args.progress,
                             workers=args.workers)
    if args.json:
        print(json.dumps(metrics, indent=2))
    else:
        print(format_report(metrics))
    return 0


def _eval_batched(args) -> int:
    """`tracker eval --assist ...`: the walk protocol on the batched env (tracker.track.walk_protocol)."""
    from dataclasses import replace

    from tracker.track.assist import AssistConfig
    from tracker.track.assisted_policy import CheckpointError, load_assisted
    from tracker.track.batch_env import BatchConfig
    from tracker.track.evaluation import draw_walks, make_setup
    from tracker.track.pd import STANCE_GAINS, PDTracker, batched_model_options
    from tracker.track.walk_protocol import format_summary, run_walks, summarise
    from tracker.track.walks import walk_source
    assist = args.assist or "learned"
    name = "learned" if args.controller in ("learned", "assisted") else args.controller
    if name not in ("pd", "learned"):
        print("igraph-fight tracker eval: with --assist the controller is pd or learned (the assisted tracker)",
              file=sys.stderr)
        return 2
    if assist == "learned" and name != "learned":
        print("igraph-fight tracker eval: --assist learned needs --controller learned", file=sys.stderr)
        return 2
    if args.cap is not None and not 0.0 < args.cap <= 2.0:
        print("igraph-fight tracker eval: --cap must lie in (0, 2] body weights", file=sys.stderr)
        return 2
    if args.parallel < 1:
        print("igraph-fight tracker eval: --parallel must be >= 1", file=sys.stderr)
        return 2
    if name == "learned":
        try:
            ctrl = load_assisted(args.ckpt, assist_off=assist == "none")
        except CheckpointError as e:
            print(f"igraph-fight tracker eval: {e}", file=sys.stderr)
            return 2
        if assist == "fixed":
            ctrl.assist_off = True
        cfg_a = ctrl.assist_config() if assist == "learned" else AssistConfig(assist, 0.0 if assist == "none" else 0.5)
        hz = ctrl.physics_hz
    else:
        ctrl = PDTracker(class_scale=STANCE_GAINS)
        cfg_a = AssistConfig(assist, 0.0 if assist == "none" else 0.5)
        hz = 120.0
    if args.cap is not None and assist != "none":
        cfg_a = replace(cfg_a, cap=float(args.cap))
    if args.physics_hz != 240.0:           # the flag's legacy default: the batched env's default rate is 120 Hz
        hz = float(args.physics_hz)
    src = walk_source(args.library, args.mocap, args.clips)
    setup = make_setup(src, batched_model_options(hz))
    walks = draw_walks(src, args.walks, args.actions, args.seed)
    config = BatchConfig(assist=cfg_a)
    runs, timing = run_walks(setup, ctrl, walks, config, parallel=args.parallel, progress=args.progress,
                             placement=args.placement)
    m = summarise(runs, ctrl, config, timing, args.actions, args.seed, float(setup.spec.mass_kg))
    m["physics_hz"] = hz
    print(json.dumps(m, indent=2) if args.json else format_summary(m))
    return 0


def cmd_ground(args) -> int:
    """`tracker ground`: floor statistics of the protocol's walk references, before and after grounding."""
    import numpy as np

    from tracker.track.evaluation import draw_walks, make_setup, walk_reference
    from tracker.track.grounding import floor_report
    from tracker.track.pd import batched_model_options
    from tracker.track.walks import walk_source
    src = walk_source(args.library, args.mocap, args.clips)
    setup = make_setup(src, batched_model_options(120.0))
    before, after = [], []
    for walk in draw_walks(src, args.walks, args.actions, args.seed):
        ref = walk_reference(setup, walk, lift="ground")[1]
        off = np.asarray(ref.meta["ground_offset_m"])
        feet1 = np.asarray(ref.meta["feet_after_m"])
        before.append(feet1 - off[:, None])
        after.append(feet1)
    rep = {"walks": args.walks, "actions": args.actions, "seed": args.seed,
           "before": floor_report(np.concatenate(before)), "after": floor_report(np.concatenate(after))}
    if args.json:
        print(json.dumps(rep, indent=2))
        return 0
    print(f"{args.walks} walks of {args.actions} actions (seed {args.seed}); lower foot height, frames with both feet "
          "up > 1.5 cm, penetration (cm):")
    for k, name in (("before", "as captured"), ("after", "grounded")):
        r = rep[k]
        print(f"  {name:11s}  median {r['lower_foot_median_cm']:5.2f}  p90 {r['lower_foot_p90_cm']:5.2f}  both up "
              f"{100 * r['both_up_share']:4.0f}%  penetration p95 {r['penetration_p95_cm']:.2f} max {r['penetration_max_cm']:.2f}")
    return 0


def cmd_render(args) -> int:
    from pathlib import Path

    import numpy as np

    from tracker.track.evaluation import draw_walks
    from tracker.track.reference import build_reference
    from tracker.track.render import image_stats, record_rollout, render_frames, save_contact_sheet, save_video

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".mp4"):
        print("igraph-fight: error: tracker render: --out must end in .png or .mp4", file=sys.stderr)
        return 2
    try:
        controller = _controller(args)
    except (ValueError, FileNotFoundError) as e:
        print(f"igraph-fight: error: tracker render: {e}", file=sys.stderr)
        return 2
    setup = _setup(args)
    walks = draw_walks(setup.source, args.walk_index + 1, args.actions, args.seed)
    motion = setup.source.sequence_motion(walks[args.walk_index])
    ref = build_reference(motion, setup.scene, 0, fps=setup.config.control_hz)
    ro = record_rollout(setup.scene, ref, controller, setup.config, max_s=args.seconds)
    n = len(ro.qpos)
    if out.suffix.lower() == ".png":
        steps = sorted(set(int(round(x)) for x in np.linspace(0, n - 1, max(2, args.frames))))
    else:
        stride = max(1, int(round(ref.fps / args.video_fps)))
        steps = list(range(0, n, stride))
    try:
        frames = render_frames(setup.scene, ref, ro, steps, args.width, args.height, args.backend)
    except RuntimeError as e:
        print(f"igraph-fight: error: tracker render: {e}", file=sys.stderr)
        return 1
    if out.suffix.lower() == ".png":
        save_contact_sheet(frames, out)
    else:
        try:
            save_video(frames, out, ref.fps / max(1, int(round(ref.fps / args.video_fps))))
        except RuntimeError as e:
            print(f"igraph-fight: error: tracker render: {e}", file=sys.stderr)
            return 1
    st = image_stats(frames[0][1])
    fell = f"fell at {ro.fall_step / ref.fps:.2f} s ({ro.fall_reason})" if ro.fall_step is not None else "no fall"
    print(f"wrote {out}: {len(frames)} frames of walk {walks[args.walk_index]} ({controller.name}: {fell}); "
          f"first simulation frame foreground {100 * st['foreground_share']:.0f}%")
    return 0


def cmd_train(args) -> int:
    from tracker.learn.train_tracker import main_args
    return main_args(args)


def cmd_train_assisted(args) -> int:
    from tracker.learn.overrides import parse_config_overrides
    from tracker.learn.train_assisted import AssistedTrainConfig, train
    if not args.minutes > 0:
        print("igraph-fight tracker train-assisted: --minutes must be positive", file=sys.stderr)
        return 2
    try:
        overrides = parse_config_overrides(args.set or [], AssistedTrainConfig)
        cfg = AssistedTrainConfig(**overrides)
    except ValueError as e:
        print(f"igraph-fight tracker train-assisted: {e}", file=sys.stderr)
        return 2
    r = train(args.out, args.minutes, cfg, library=args.library, resume=args.resume, progress=not args.no_progress,
              overrides=overrides)
    b = r["budget"]
    print(f"wrote {r['out']} (and {r['out']}.png): {b['samples'] / 1e6:.2f}M samples, {b['cpu_s'] / 3600:.2f} CPU-hours "
          f"over {b['runs']} run(s), assist cap now {r['cap']:.3f} mg")
    return 0


def cmd_train_assisted_bouts(args) -> int:
    from dataclasses import fields
    from tracker.learn.overrides import parse_config_overrides
    from tracker.learn.train_assisted import AssistedTrainConfig
    from tracker.learn.train_assisted_bouts import BoutTrainConfig, train_in_bouts
    name = "igraph-fight tracker train-assisted-bouts"
    if not args.minutes > 0:
        print(f"{name}: --minutes must be positive", file=sys.stderr)
        return 2
    bout_keys = {f.name for f in fields(BoutTrainConfig)}
    items = args.set or []
    try:
        bout_over = parse_config_overrides([i for i in items if i.partition("=")[0] in bout_keys], BoutTrainConfig)
        ppo_over = parse_config_overrides([i for i in items if i.partition("=")[0] not in bout_keys],
                                          AssistedTrainConfig)
        r = train_in_bouts(args.out, args.minutes, args.graph, resume=args.resume,
                           bout_cfg=BoutTrainConfig(**bout_over), overrides=ppo_over, progress=not args.no_progress)
    except ValueError as e:
        print(f"{name}: {e}", file=sys.stderr)
        return 2
    b = r["budget"]
    print(f"wrote {r['out']} (and {r['out']}.png): {r['bouts']} bouts, {b['samples'] / 1e6:.2f}M samples in all, "
          f"{b['cpu_s'] / 3600:.2f} CPU-hours over {b['runs']} run(s); assisted physics, cap {r['cap']:.3f} mg")
    return 0


def cmd_model(args) -> int:
    from pathlib import Path

    from motion_graph.io import load_motion

    from tracker.body.humanoid import ModelOptions, build_fighter_scene
    from tracker.body.spec import fighter_spec
    m = load_motion(args.file)
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, args.fighters, ModelOptions(physics_hz=args.physics_hz))
    Path(args.out).write_text(scene.xml)
    f = scene.fighters[0]
    print(f"wrote {args.out}: {args.fighters} fighter(s), {len(f.dof_joints)} ball joints + free root, "
          f"{f.n_act} actuators each, {spec.mass_kg:g} kg, height {spec.height_m:.2f} m")
    return 0


def physics_fight(args) -> int:
    """`igraph-fight fight --physics ...` (the igraph_fight.physics entry point)."""
    from tracker.bouts.cli import cmd_physics_fight
    return cmd_physics_fight(args)
