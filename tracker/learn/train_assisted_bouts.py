"""Training the assisted tracker inside physics bouts: PPO on the bouts the product plays.

    igraph-fight tracker train-assisted-bouts --graph G.igz --minutes 60 --out a.pt [--resume a.pt] [--set k=v ...]

Walks (tracker.learn.train_assisted) hold neither the opponent nor the planner's sequences of
actions, each placed at the body's predicted pose as a bout places it; a tracker trained on walks
alone falls more in bouts than in walks. This route continues an assisted-tracker checkpoint
inside physics bouts (tracker.bouts.physics_bout, the bout rules unchanged). Read top to bottom:

1. ``BoutTrainConfig``: the bout knobs (styles, planner depth, seconds per bout, seeds). The PPO
   knobs are the checkpoint's ``AssistedTrainConfig`` (stored with it; ``--set`` sets either).
2. ``SamplingTracker``: the assisted controller with Gaussian exploration (the policy's own
   standard deviations); per control step it keeps both fighters' raw and normalised observations,
   actions, log-probabilities and values.
3. ``collect``: one bout per iteration between planner fighters of the two styles (sides swapped
   every other bout), seeds ``seed0 + bout index`` (far from the evaluation seeds). A fighter's
   control steps while it stands are its trajectory: a fall terminates it (value 0 after), the
   bout's end cuts it (bootstrapped); the steps it lies down are not samples. Reward: the batched
   env's tracking terms times the assist penalty (as in walk training), per fighter, plus an
   optional strike term (``strike_reward``, off by default): inside the fighter's strike windows,
   closeness of the strike's fist to the opponent's target, and a bonus per hit landed.
4. ``train_assisted.ppo_update`` on the iteration's samples; the observation normaliser updated
   after it (the batch used the old statistics). Then ``walks_per_bout`` iterations of the walk
   route (``train_assisted.collect_walks``, its pushes included) on the same library, so that what
   the bouts teach does not erase the walks of every action the bouts rarely play.
5. ``train_in_bouts``: the loop, a progress bar, a checkpoint (the walk trainer's format, resumable
   by either route) every ``ckpt_every_min`` minutes and at the end, atomically; ``bout_curve``
   rows (reward, falls per fighter and minute, mean wrench, planned hits realised) and a PNG
   beside it; the budget in CPU-hours accumulates over runs of both routes.

The assist cap stays the checkpoint's (no curriculum here): bouts are where the cap is judged.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

from igraph_fight.learn.ppo import gae
from tracker.learn.train_assisted import (
    AssistedTrainConfig, Rollouts, RunningNorm, assisted_nets, collect_walks, plain_config, ppo_update,
    reward_weights)
from tracker.track.assisted_policy import FORMAT, N_ASSIST, VERSION, actor_layers, mlp_forward


@dataclass
class BoutTrainConfig:
    """The bout side of a run (module docstring, item 1)."""

    styles: tuple = ("infighter", "outboxer")
    depth: int = 5
    bout_seconds: float = 60.0
    seed0: int = 1_000_000
    noise_seed: int = 0
    walks_per_bout: int = 2
    strike_weight: float = 0.0
    strike_scale_m: float = 0.05
    hit_bonus: float = 0.0

    def __post_init__(self) -> None:
        if not self.strike_weight >= 0 or not self.strike_scale_m > 0 or not self.hit_bonus >= 0:
            raise ValueError("strike_weight and hit_bonus must be >= 0 and strike_scale_m > 0, got "
                             f"{self.strike_weight}, {self.hit_bonus}, {self.strike_scale_m}")

    @classmethod
    def from_dict(cls, d: dict) -> "BoutTrainConfig":
        known = {f.name for f in fields(cls)}
        return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items() if k in known})


class SamplingTracker:
    """The assisted controller's protocol (tracker.track.assisted_policy.AssistedController) with
    exploration: actions drawn from the policy's Gaussian; ``last`` holds the step's
    (raw obs, normalised obs, action, log-probability, value), one row per fighter."""

    name = "learned"
    batched = True

    def __init__(self, n_act: int, cap: float, cfg: AssistedTrainConfig, seed: int) -> None:
        from tracker.track.pd import PDTracker
        self.n_act = n_act
        self.cap = float(cap)
        self.cfg = cfg
        self.physics_hz = float(cfg.physics_hz)
        self.rng = np.random.default_rng(seed)
        self.pd = PDTracker(class_scale=cfg.class_scale, arm_velocity_targets=cfg.arm_velocity_targets)
        self.last: tuple | None = None

    def load(self, actor, critic, norm: RunningNorm) -> None:
        """Take the current weights (torch modules) and normaliser statistics."""
        sa = {k: v.detach().cpu().numpy() for k, v in actor.state_dict().items()}
        sc = {k: v.detach().cpu().numpy() for k, v in critic.state_dict().items()}
        self.layers = actor_layers(sa)
        self.critic_layers = actor_layers(sc, prefix="")
        self.log_std = sa["log_std"].astype(np.float64)
        self.assist_gain = sa["assist_gain"].astype(np.float64)
        self.norm = norm

    def reset(self, env) -> None:
        self.pd.reset(env)

    def assist_config(self):
        from tracker.track.assist import AssistConfig
        return AssistConfig("learned", self.cap)

    def act(self, env, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.atleast_2d(np.asarray(obs, dtype=np.float64))
        z = self.norm(x)
        mu = mlp_forward(self.layers, z)
        mu[:, self.n_act:] += x[:, -N_ASSIST:] * self.assist_gain
        std = np.exp(self.log_std)
        eps = self.rng.standard_normal(mu.shape)
        a = mu + std * eps
        lp = (-0.5 * eps ** 2 - self.log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
        v = mlp_forward(self.critic_layers, z)[:, 0]
        self.last = (x.copy(), z, a, lp, v)
        clip = self.cfg.residual_clip
        targets = env.reference_targets() + np.clip(a[:, :self.n_act], -clip, clip)
        return targets, np.clip(a[:, self.n_act:], -1.0, 1.0)

    def value(self, obs: np.ndarray) -> np.ndarray:
        return mlp_forward(self.critic_layers, self.norm(np.atleast_2d(obs)))[:, 0]

    def describe(self) -> str:
        return f"assisted tracker in training (cap {self.cap:g} mg, exploring)"


def strike_reward(bout, k: int, t: int, n_hits: int, bc: "BoutTrainConfig") -> float:
    """The strike term of fighter k at control step t (module docstring, item 3): while a strike
    window of its current action is open (as the hit judge widens it, strike not landed yet),
    ``strike_weight`` exp(-gap / ``strike_scale_m``), gap the strike fist's distance to the
    opponent's head, chest or belly; plus ``hit_bonus`` per hit it landed this step (hit events from
    index ``n_hits`` on). Zero while either fighter is down."""
    if bout.F[0].down or bout.F[1].down:
        return 0.0
    r = 0.0
    if bc.strike_weight > 0:
        for side in (0, 1):
            if bout.judge.strike_for(bout.F[k], side, t) is not None:
                gap = bout.judge.fist_target_distance(bout.env.data, k, 1 - k, side)
                r = max(r, bc.strike_weight * math.exp(-gap / bc.strike_scale_m))
    if bc.hit_bonus > 0:
        r += bc.hit_bonus * sum(1 for h in bout.hit_events[n_hits:] if h["attacker"] == k)
    return r


def collect(bout, sampler: SamplingTracker, seed: int, cfg: AssistedTrainConfig,
            bc: "BoutTrainConfig | None" = None) -> tuple[dict, dict]:
    """Play one bout with the sampler; the samples of both fighters (arrays over their standing
    steps, advantages and returns by GAE per trajectory) and the bout's summary. ``bc``: the strike
    term's weights (strike_reward; none by default)."""
    bout.start(seed)
    rows: list[list[tuple]] = [[], []]
    strikes = bc is not None and (bc.strike_weight > 0 or bc.hit_bonus > 0)
    for _ in range(bout.n_steps):
        down = [f.down for f in bout.F]
        n_hits = len(bout.hit_events)
        bout.step()
        t = bout.env.t
        x, z, a, lp, v = sampler.last
        rew, fall = bout.step_reward, bout.step_info.fall
        for k in (0, 1):
            if not down[k]:
                r = float(rew[k]) + (strike_reward(bout, k, t, n_hits, bc) if strikes else 0.0)
                rows[k].append((x[k], z[k], a[k], lp[k], v[k], r, fall[k] is not None))
    v_end = sampler.value(bout.observation)
    summary = bout.finish().summary()
    parts = {key: [] for key in ("raw", "z", "a", "lp", "adv", "ret", "r")}
    for k in (0, 1):
        if not rows[k]:
            continue
        raw, z, a, lp, v, r, term = (np.array(c) for c in zip(*rows[k]))
        nv = np.append(v[1:], v_end[k])
        nv[term] = 0.0
        cont = (~term).astype(np.float64)
        cont[-1] = 0.0                      # the bout's end cuts the last trajectory (bootstrapped)
        adv, ret = gae(r, v, nv, cont, cfg.gamma, cfg.lam)
        for key, val in (("raw", raw), ("z", z), ("a", a), ("lp", lp), ("adv", adv), ("ret", ret), ("r", r)):
            parts[key].append(val)
    batch = {k: np.concatenate(v) for k, v in parts.items()} if parts["r"] else {}
    return batch, summary


def train_in_bouts(out: str, minutes: float, graph, resume: str | None = None,
                   bout_cfg: BoutTrainConfig = BoutTrainConfig(), overrides: dict | None = None,
                   progress: bool = True, log=print, max_iterations: int | None = None) -> dict:
    """Continue the assisted tracker ``resume`` (default: the shipped one) in physics bouts on
    ``graph`` (an InteractionGraph or its file) for ``minutes`` of wall clock (or
    ``max_iterations`` bouts); write ``out`` (and ``out``.png). ``overrides``: fields of
    AssistedTrainConfig replacing the checkpoint's."""
    import torch

    from igraph_fight.checkpoint import load_checkpoint, save_checkpoint
    from igraph_fight.graph import load_graph
    from tracker.bouts.loaders import make_agent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.setup import BoutConfig, BoutSetup
    from tracker.track.assisted_policy import DEFAULT_ASSISTED_CKPT

    if not minutes > 0 and max_iterations is None:
        raise ValueError(f"minutes must be positive, got {minutes}")
    if len(bout_cfg.styles) != 2:
        raise ValueError(f"styles must name two fighters, got {bout_cfg.styles!r}")
    if bout_cfg.walks_per_bout < 0:
        raise ValueError(f"walks_per_bout must be >= 0, got {bout_cfg.walks_per_bout}")
    torch.set_num_threads(1)
    path = str(resume or DEFAULT_ASSISTED_CKPT)
    prior = load_checkpoint(path, FORMAT, (VERSION,), "assisted-tracker checkpoint")
    cfg = AssistedTrainConfig.from_dict({**asdict(AssistedTrainConfig()), **prior["config"], **(overrides or {})})
    g = load_graph(graph) if not hasattr(graph, "arrays") else graph
    lib = g.load_library()
    budget = dict(prior["budget"])
    budget["runs"] += 1
    cap = float(prior["cap"])
    sampler = SamplingTracker(0, cap, cfg, bout_cfg.noise_seed * 1000 + budget["runs"])
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), tracker=sampler, reward=reward_weights(cfg))
    sampler.n_act = setup.env.batch.n_act
    obs_dim = int(np.asarray(prior["obs_mean"]).shape[0])
    act_dim = sampler.n_act + N_ASSIST
    actor, critic = assisted_nets(obs_dim, act_dim, cfg)
    actor.load_state_dict(prior["actor"])
    critic.load_state_dict(prior["critic"])
    opt = torch.optim.Adam(list(actor.parameters()) + list(critic.parameters()), lr=cfg.lr)
    opt.load_state_dict(prior["optimizer"])
    norm = RunningNorm(obs_dim)
    norm.mean = np.asarray(prior["obs_mean"], float)
    norm.var = np.asarray(prior["obs_var"], float)
    norm.count = float(prior["obs_count"])
    bout_curve = list(prior.get("bout_curve", []))
    roll = None
    walk_done: list[float] = []
    if bout_cfg.walks_per_bout > 0:
        roll = Rollouts(cfg, lib, cfg.seed * 1000 + budget["runs"])
        roll.set_cap(cap)
        if roll.obs.shape[1] != obs_dim:
            raise ValueError(f"walk observations have {roll.obs.shape[1]} values, the checkpoint {obs_dim}")
    agents = {s: make_agent(s, g, lib, bout_cfg.depth) for s in bout_cfg.styles}
    bcfg = replace(BoutConfig(), seconds=float(bout_cfg.bout_seconds), record_qpos=False)
    done_bouts = len(bout_curve)
    cpu0, wall0 = time.process_time(), time.perf_counter()
    cpu_base, wall_base = budget["cpu_s"], budget["wall_s"]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=int(minutes * 60), desc="train-assisted-bouts", unit="s")
    last_ckpt = time.perf_counter()

    def save() -> None:
        budget["cpu_s"] = cpu_base + time.process_time() - cpu0
        budget["wall_s"] = wall_base + time.perf_counter() - wall0
        config = {**plain_config(asdict(cfg)), "bout_training": plain_config(asdict(bout_cfg))}
        ck = {"actor": actor.state_dict(), "critic": critic.state_dict(), "optimizer": opt.state_dict(),
              "obs_mean": norm.mean, "obs_var": norm.var, "obs_count": float(norm.count), "config": config,
              "cap": cap, "budget": dict(budget), "curve": list(prior["curve"]),
              "completions": list(prior.get("completions", [])), "bout_curve": bout_curve,
              "torch_version": torch.__version__}
        save_checkpoint(out, ck, FORMAT, VERSION)
        plot_bout_curve(bout_curve, str(out) + ".png")

    it = 0
    while True:
        if time.perf_counter() - wall0 >= minutes * 60 or (max_iterations is not None and it >= max_iterations):
            break
        i = done_bouts + it
        a_style, b_style = bout_cfg.styles if i % 2 == 0 else bout_cfg.styles[::-1]
        sampler.load(actor, critic, norm)
        bout = PhysicsBout(setup, [agents[a_style], agents[b_style]], sampler, bcfg)
        t0 = time.perf_counter()
        batch, s = collect(bout, sampler, bout_cfg.seed0 + i, cfg, bout_cfg)
        n = len(batch.get("r", ()))
        kl = float("nan")
        if n >= 2:
            fx = batch["raw"][:, -N_ASSIST:]
            kl = ppo_update(actor, critic, opt, batch["z"], fx, batch["a"], batch["lp"], batch["adv"], batch["ret"],
                            cfg, cfg.seed * 100_003 + budget["iterations"])
            norm.update(batch["raw"])
        budget["samples"] += n
        budget["iterations"] += 1
        n_walk = 0
        for _ in range(bout_cfg.walks_per_bout):
            wb = collect_walks(roll, actor, critic, norm, cfg, walk_done)
            ppo_update(actor, critic, opt, wb["z"], wb["fx"], wb["a"], wb["lp"], wb["adv"], wb["ret"], cfg,
                       cfg.seed * 100_003 + budget["iterations"])
            norm.update(wb["raw"])
            roll.refresh()
            roll.finished = []
            n_walk += len(wb["r"])
            budget["samples"] += len(wb["r"])
            budget["iterations"] += 1
        del walk_done[:-cfg.curriculum_window]
        it += 1
        minutes_bout = float(s["seconds"]) / 60.0
        row = {"samples": int(budget["samples"]), "cpu_h": (cpu_base + time.process_time() - cpu0) / 3600,
               "bout": i, "a": a_style, "b": b_style, "bout_samples": n, "walk_samples": n_walk,
               "walk_completion": float(np.mean(walk_done)) if walk_done else float("nan"),
               "reward_per_step": float(batch["r"].mean()) if n else float("nan"),
               "falls_per_min": (s["falls_a"] + s["falls_b"]) / (2.0 * minutes_bout),
               "assist_mg": 0.5 * (s["assist_a"]["force_mean_mg"] + s["assist_b"]["force_mean_mg"]),
               "planned_hits": float(s["planned_hits"]), "planned_realised": float(s["planned_realised"]),
               "kl": kl, "lr": float(opt.param_groups[0]["lr"]), "std": float(actor.log_std.detach().exp().mean()),
               "steps_per_s": n / max(time.perf_counter() - t0, 1e-9)}
        bout_curve.append(row)
        if bar is not None:
            bar.n = int(min(time.perf_counter() - wall0, minutes * 60))
            recent = bout_curve[-10:]
            bar.set_postfix(falls=f"{np.mean([r['falls_per_min'] for r in recent]):.2f}",
                            assist=f"{row['assist_mg']:.3f}", walks=f"{row['walk_completion']:.2f}",
                            sps=f"{row['steps_per_s']:.0f}")
            bar.refresh()
        elif log is not None and it % 10 == 0:
            log(row)
        if time.perf_counter() - last_ckpt > cfg.ckpt_every_min * 60:
            save()
            last_ckpt = time.perf_counter()
    if bar is not None:
        bar.close()
    save()
    return {"out": str(out), "budget": budget, "cap": cap, "bouts": it, "last": bout_curve[-1] if bout_curve else {}}


def plot_bout_curve(curve: list[dict], path: str, window: int = 20) -> None:
    """Learning curve of bout training: reward per step, falls per fighter and minute, mean wrench
    and the share of planned hits realised against samples (running means over ``window`` bouts)."""
    if not curve:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from motion_graph.atomic import atomic_write
    x = np.array([r["samples"] for r in curve]) / 1e6

    def smooth(v):
        v = np.asarray(v, float)
        k = min(window, len(v))
        return np.convolve(v, np.ones(k) / k, mode="valid"), x[k - 1:]

    ph = np.array([r["planned_hits"] for r in curve])
    pr = np.array([r["planned_realised"] for r in curve])
    series = (("reward_per_step", [r["reward_per_step"] for r in curve], "reward per step"),
              ("falls_per_min", [r["falls_per_min"] for r in curve], "falls per fighter and minute"),
              ("assist_mg", [r["assist_mg"] for r in curve], "mean |F| / mg"),
              ("realised", None, "planned hits realised"))
    walks = [r.get("walk_completion", float("nan")) for r in curve]
    if np.isfinite(walks).any():
        series += (("walk_completion", walks, "walk episodes completed (last 200)"),)
    fig, ax = plt.subplots(1, len(series), figsize=(4 * len(series), 3.4))
    for a, (key, vals, title) in zip(ax, series):
        if key == "realised":
            k = min(window, len(ph))
            num = np.convolve(pr, np.ones(k), mode="valid")
            den = np.convolve(ph, np.ones(k), mode="valid")
            a.plot(x[k - 1:], np.divide(num, den, out=np.zeros_like(num), where=den > 0), lw=1)
        else:
            y, xs = smooth(vals)
            a.plot(xs, y, lw=1)
        a.set_title(title)
        a.set_xlabel("samples (M)")
        a.grid(alpha=0.3)
    fig.suptitle(f"assisted tracker training in physics bouts (assisted physics; running means over {window} bouts)")
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=90))
    plt.close(fig)
