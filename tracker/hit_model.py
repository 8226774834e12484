"""Physically measured hit odds for the Interaction Graph fighter's first ply (issue 8).

In physics bouts the planner's kinematic hit predictions hold for about 12% of its planned hits
(tracker/BOUTS.md): the bodies are not where each reference's displacement puts them. This
module learns from physics bouts what the kinematic simulator cannot know: the odds that an
action launched now lands at least one realised hit (``given``) and that the fighter is hit
while it plays it (``received``), from the live coupled state, the physical features of both
bodies (PhysicsBout.features: pelvis heights, tilts, velocities, down flags, fist-to-target
distances both ways), the opponent's action kind and the action's exact one-step kinematic
terms (NPCController.menu_terms). ``PhysIGAgent`` is the IG fighter with those odds in place of
the kinematic damage terms of its first ply:

    q(a) = -pos(a) + w_given * pref(kind a) * P_given(a) - w_received * P_received(a) + def(a) + gamma V(a)

where V is the policy table's value where the action lands. ``phys_fighter(future=...)`` picks
that table: "calibrated" (default) computes it for the style with its hit weights scaled by how
often a kinematically predicted hit was realised in the model's held-out bouts, so the later
plies expect hits at their physical rate; "physical" keeps the style's weights and replaces the
graph's damage features by physically expected ones (per attack kind, including the strikes the
simulator says miss, which land too); "kinematic" uses the style's own table; "none" drops V
(the first ply alone). Measured against the physics RL baseline in tracker/BOUTS.md.

Data come from bouts with exploration (a share of each IG fighter's decisions uniform over its
menu) against the RL baseline and other IG fighters, on seeds apart from the evaluation's; the
RL fighter's own decisions are samples too. Labels: ``given`` = the action instance produced a
realised hit (tracker.judging); ``received`` = a realised hit on the fighter between its decision
instant and the action's nominal end (``fell``, a fall in that span, is recorded, not modelled).
Named approximations: the odds are those of the collection's opponents, exploration rate and
tracking policy, not of every opponent or tracker; the later plies' calibration is one rate per head, not per state.

    python -m tracker.hit_model collect --graph G.igz --bouts 240 --explore 0.4 --out r1.npz [--workers 2]
    python -m tracker.hit_model collect --graph G.igz --bouts 160 --seed0 2000 --explore 0.25 --hit-model M1.pt --future kinematic --out r2.npz
    python -m tracker.hit_model train --data r1.npz r2.npz ... --out tracker/checkpoints/hit_model_cmu13.pt   # + .png reliability plot
    python -m tracker.hit_model kinds --data r1.npz ... --graph G.igz      # per action kind: landed, hit, falls
    igraph-fight fight --physics --graph G.igz --a infighter+phys --b rl ...      # the fighter; +phys:MODEL for another model
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

DEFAULT_HIT_MODEL = Path(__file__).resolve().parent / "checkpoints" / "hit_model_cmu13.pt"

#: kinematic features taken from NPCController.menu_terms' raw sim.FT_* columns
_FT_USED = (0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 14, 15)
N_PHYS = 14      # PhysicsBout.features


def feature_vector(obs, phys: np.ndarray, mt: np.ndarray, kind_other: int, n_actions: int,
                   n_kinds: int) -> np.ndarray:
    """Model inputs for each row of ``mt`` (NPCController.menu_terms, one row per candidate
    action): action one-hot, the row's kinematic features, the coupled state (r m, |angles| rad,
    the opponent's frame at 30 fps in s), the opponent's action kind one-hot and the physical
    features. Shape (rows, n_actions + 14 + 4 + n_kinds + 14)."""
    from igraph_fight.controller import MT_ACTION, MT_FT
    n = mt.shape[0]
    X = np.zeros((n, n_actions + len(_FT_USED) + 4 + n_kinds + N_PHYS))
    X[np.arange(n), mt[:, MT_ACTION].astype(np.int64)] = 1.0
    c = n_actions
    X[:, c:c + len(_FT_USED)] = mt[:, [MT_FT + i for i in _FT_USED]]
    c += len(_FT_USED)
    X[:, c:c + 4] = [obs.r, abs(obs.theta_self), abs(obs.theta_other), obs.f_other / 30.0]
    c += 4
    if 0 <= kind_other < n_kinds:
        X[:, c + kind_other] = 1.0
    c += n_kinds
    X[:, c:c + N_PHYS] = np.asarray(phys, dtype=np.float64)[:N_PHYS]
    return X


# ----------------------------------------------------------------------------------------------
# the model


@dataclass
class HitModelConfig:
    """Training hyper-parameters (the whole configuration of ``train``)."""

    hidden: tuple = (32,)
    epochs: int = 20
    batch: int = 256
    lr: float = 2e-3
    weight_decay: float = 1e-4
    holdout: float = 0.2          # share of bouts (by seed) held out for the report
    seed: int = 0


class HitModel:
    """Two logistic heads (P_given, P_received) over a small MLP, inputs standardised."""

    def __init__(self, net, mean: np.ndarray, std: np.ndarray, meta: dict) -> None:
        self.net = net
        self.mean = mean.astype(np.float32)
        self.std = std.astype(np.float32)
        self.meta = meta
        self._layers = None     # numpy copies of the weights (a decision's few rows: numpy beats torch's overhead)

    def predict(self, X: np.ndarray) -> np.ndarray:
        """(rows, 2) probabilities: column 0 given, column 1 received."""
        if self._layers is None:
            mods = list(self.net) if hasattr(self.net, "__iter__") else [self.net]   # Sequential or one Linear
            self._layers = [(m.weight.detach().numpy().T.astype(np.float64), m.bias.detach().numpy().astype(np.float64))
                            for m in mods if hasattr(m, "weight")]
        h = (np.asarray(X, dtype=np.float64) - self.mean) / self.std
        for i, (W, b) in enumerate(self._layers):
            h = h @ W + b
            if i < len(self._layers) - 1:
                h = np.tanh(h)
        from scipy.special import expit
        return expit(h)

    def save(self, path: str | os.PathLike) -> None:
        import torch
        from motion_graph.atomic import atomic_write
        ck = {"model": self.net.state_dict(), "mean": self.mean, "std": self.std, "meta": self.meta}
        atomic_write(Path(path), lambda fh: torch.save(ck, fh))


def _mlp(n_in: int, hidden: tuple):
    import torch.nn as nn
    layers, d = [], n_in
    for h in hidden:
        layers += [nn.Linear(d, h), nn.Tanh()]
        d = h
    layers.append(nn.Linear(d, 2))
    return nn.Sequential(*layers)


def load_hit_model(path: str | os.PathLike | None = None) -> HitModel:
    """A trained hit model (default: the shipped tracker/checkpoints/hit_model_cmu13.pt)."""
    import torch
    p = Path(path) if path else DEFAULT_HIT_MODEL
    if not p.is_file():
        raise FileNotFoundError(f"no hit model at {p} (train one: python -m tracker.hit_model collect ... ; train ...)")
    try:
        ck = torch.load(p, map_location="cpu", weights_only=False)
        net = _mlp(int(ck["meta"]["n_in"]), tuple(ck["meta"]["hidden"]))
        net.load_state_dict(ck["model"])
    except Exception as e:  # a clear error naming the file, not a traceback from inside torch
        raise ValueError(f"{p}: not a hit model checkpoint ({type(e).__name__}: {e})") from None
    net.eval()
    return HitModel(net, np.asarray(ck["mean"]), np.asarray(ck["std"]), dict(ck["meta"]))


# ----------------------------------------------------------------------------------------------
# the agent


#: how PhysIGAgent values the plies after the first (the graph's policy values where an action lands)
FUTURES = ("calibrated", "physical", "kinematic", "none")


def physical_edge_features(graph_arrays, model: HitModel, action_kinds, kind_names) -> dict:
    """The graph's damage features as physically expected (``future="physical"``): an edge whose
    event the kinematic simulator says lands dg damage expects rate_hit(kind) * dg, a strike it
    says misses still expects rate_miss(kind) (strikes land without a kinematic prediction too),
    and damage received is scaled by the received rate when predicted. Rates per attack kind from
    the model's training data (meta ``action_rates``: per action, decisions and landed with and
    without a kinematic prediction), pooled over the kind's actions."""
    from motion_graph.classify import ATTACK_KINDS
    ar = np.asarray(model.meta.get("action_rates", []), dtype=np.float64)
    if ar.ndim != 2 or ar.shape[0] != len(action_kinds):
        raise ValueError("hit model has no per-action rates (retrain it with this version) for future='physical'")
    kinds = np.asarray(action_kinds, dtype=np.int64)
    nk = len(kind_names)
    tot = ar.sum(0)
    hit, miss = np.zeros(nk), np.zeros(nk)
    for k in range(nk):
        s = ar[kinds == k].sum(0)
        hit[k] = s[1] / s[0] if s[0] > 0 else tot[1] / max(tot[0], 1)
        miss[k] = s[3] / s[2] if s[2] > 0 and kind_names[k] in ATTACK_KINDS else 0.0
    fk = np.asarray(graph_arrays["feat_kind"], dtype=np.int64)
    ok = (fk >= 0) & (fk < nk)
    fkc = np.clip(fk, 0, nk - 1)
    dg = np.asarray(graph_arrays["feat_dmg_given"], dtype=np.float64)
    given = np.where(ok, np.where(dg > 0, hit[fkc] * dg, miss[fkc]), dg)
    rr = float(model.meta["report"]["received"]["rate_when_kinematic_predicts"])
    received = rr * np.asarray(graph_arrays["feat_dmg_received"], dtype=np.float64)
    return {"feat_dmg_given": given.astype(graph_arrays["feat_dmg_given"].dtype),
            "feat_dmg_received": received.astype(graph_arrays["feat_dmg_received"].dtype)}


def calibrated_style(style, model: HitModel):
    """``style`` with its hit terms (w_dmg_given, w_dmg_received, w_def) scaled by how often a
    kinematically predicted hit was realised in the model's held-out bouts (report's
    ``rate_when_kinematic_predicts``, given and received): the policy table's later plies then
    expect hits at their physical rate instead of the kinematic simulator's certainty."""
    from dataclasses import replace
    rep = model.meta.get("report", {})
    try:
        rg = float(rep["given"]["rate_when_kinematic_predicts"])
        rr = float(rep["received"]["rate_when_kinematic_predicts"])
    except (KeyError, TypeError):
        raise ValueError("hit model has no held-out report (train it with holdout > 0) to calibrate the "
                         "later plies; use future='kinematic'") from None
    return replace(style, name=f"{style.name}~phys", w_dmg_given=style.w_dmg_given * rg,
                   w_dmg_received=style.w_dmg_received * rr, w_def=style.w_def * rr)


class PhysIGAgent:
    """An IG fighter whose first ply scores every legal action with the physically measured hit
    odds in place of the kinematic damage terms (module docstring), under ``style`` (the
    controller's style by default). The later plies are the controller's policy values:
    ``future`` says what the controller's table is ("kinematic": the style's own; "calibrated":
    calibrated_style's, built by phys_fighter; "none": the values are ignored)."""

    def __init__(self, controller, model: HitModel, name: str | None = None, style=None,
                 future: str = "kinematic") -> None:
        if future not in FUTURES:
            raise ValueError(f"future must be one of {', '.join(FUTURES)}, not {future!r}")
        lib = controller.library
        if int(model.meta["n_actions"]) != lib.n_actions:
            raise ValueError(f"hit model was trained on {model.meta['n_actions']} actions, the library has "
                             f"{lib.n_actions}")
        self.controller = controller
        self.model = model
        self.style = style
        self.future = future
        self.value_scale = 0.0 if future == "none" else 1.0
        self.name = name or f"{(style or controller.style_def).name}({controller.depth}, phys)"
        self.kinds = np.asarray(controller.action_kinds, dtype=np.int64)
        self.n_kinds = int(model.meta["n_kinds"])
        self.decisions = 0
        self.off_graph = 0
        self._pref = (None, None)      # (style, its kind preferences)

    def reset(self, bout, k, rng) -> None:
        self.decisions = 0
        self.off_graph = 0

    def scores(self, ctx) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(menu_terms rows, model odds (rows, 2), scores) for a decision context."""
        from igraph_fight.controller import MT_DEF, MT_POS, MT_VALUE
        from planner import kind_preferences
        c = self.controller
        mt = c.menu_terms(ctx.obs)
        X = feature_vector(ctx.obs, ctx.features, mt, int(self.kinds[int(ctx.obs.m_other)]), c.library.n_actions,
                           self.n_kinds)
        p = self.model.predict(X)
        st = self.style or c.style_def
        if self._pref[0] is not st:
            self._pref = (st, kind_preferences(st, c.kind_names))
        pref = self._pref[1]
        k = self.kinds[mt[:, 0].astype(np.int64)]
        pk = np.where((k >= 0) & (k < len(pref)), pref[np.clip(k, 0, len(pref) - 1)], 1.0)
        q = (-mt[:, MT_POS] + st.w_dmg_given * pk * p[:, 0] - st.w_dmg_received * p[:, 1] + mt[:, MT_DEF]
             + self.value_scale * mt[:, MT_VALUE])
        return mt, p, q

    def set_style(self, style) -> None:
        """Switch style at run time (the controller's table recomputed, calibrated if ``future`` is)."""
        from planner import Style, load_style
        st = style if isinstance(style, Style) else load_style(style)
        self.controller.set_style(calibrated_style(st, self.model) if self.future == "calibrated" else st, wait=True)
        self.style = st

    def decide(self, ctx) -> int:
        self.decisions += 1
        self.off_graph += int(self.controller.locate(ctx.obs)[2])
        return self.peek(ctx)

    def peek(self, ctx) -> int:
        """What decide() answers for ``ctx``, without counting it (it is deterministic)."""
        mt, _, q = self.scores(ctx)
        return int(ctx.menu[0]) if len(q) == 0 else int(mt[int(np.argmax(q)), 0])


def phys_fighter(graph, library, style, depth: int, model: HitModel | str | None = None,
                 future: str = "calibrated") -> PhysIGAgent:
    """A PhysIGAgent for a style (name, file or Style): ``future`` "calibrated" (the policy table of
    calibrated_style: later plies expect hits at the physical rate), "physical" (the style's own
    weights over physical_edge_features: per-kind rates, and strikes the simulator says miss
    still expect their measured rate), "kinematic" (the style's own table) or "none" (no later
    plies: the first ply alone)."""
    from igraph_fight.controller import NPCController
    from planner import Style, load_style
    if future not in FUTURES:
        raise ValueError(f"future must be one of {', '.join(FUTURES)}, not {future!r}")
    hm = model if isinstance(model, HitModel) else load_hit_model(model)
    st = style if isinstance(style, Style) else load_style(style)
    table_style = calibrated_style(st, hm) if future == "calibrated" else st
    feats = None
    if future == "physical":
        from igraph_fight.graph import InteractionGraph, load_graph
        from motion_graph.classify import KINDS
        g = graph if isinstance(graph, InteractionGraph) else load_graph(graph)
        graph = g
        lib = library if library is not None else g.load_library()
        names = [str(k) for k in g.arrays.get("kinds_table", KINDS)]
        feats = physical_edge_features(g.arrays, hm, np.asarray(lib.kinds, dtype=np.int64), names)
    npc = NPCController(graph, library, style=table_style, depth=depth, edge_features=feats)
    tag = "" if future == "calibrated" else f", future {future}"
    # (set_style keeps edge_features: they live in the controller's arrays)
    return PhysIGAgent(npc, hm, name=f"{st.name}({depth}, phys{tag})", style=st, future=future)


# ----------------------------------------------------------------------------------------------
# data collection


class _Recorder:
    """Wraps an agent: records each decision's inputs (for the chosen action) and, for an IG
    fighter, replaces a share ``explore`` of its choices by a uniform pick from the menu."""

    def __init__(self, inner, terms_npc, explore: float, n_kinds: int) -> None:
        self.inner = inner
        self.npc = terms_npc
        self.explore = explore
        self.n_kinds = n_kinds
        self.name = inner.name
        self.rows: list[tuple] = []

    def reset(self, bout, k, rng) -> None:
        self.bout, self.k = bout, k
        self.rng = np.random.default_rng(rng.integers(1 << 31))
        self.rows = []
        self.inner.reset(bout, k, rng)

    def decide(self, ctx) -> int:
        a = int(self.inner.decide(ctx))
        if self.explore > 0 and self.rng.random() < self.explore:
            a = int(self.rng.choice(ctx.menu))
        mt = self.npc.menu_terms(ctx.obs)
        j = int(np.nonzero(mt[:, 0].astype(np.int64) == a)[0][0])
        kinds = self.npc.action_kinds
        x = feature_vector(ctx.obs, ctx.features, mt[j:j + 1], int(kinds[int(ctx.obs.m_other)]),
                           self.npc.library.n_actions, self.n_kinds)[0]
        self.rows.append((x, int(round(ctx.t_s * 30)), a, self.bout.F[ctx.k].n_inst + 1))
        return a


def _label(rows, k: int, hits: list[dict], nf: np.ndarray, n_steps: int, falls: list[dict] = ()):
    """(X, y (given, received, fell), actions) for one fighter's recorded rows of a finished bout;
    ``fell``: the fighter's fall detected between the decision step and the action's nominal end."""
    X, y, acts = [], [], []
    for x, t0, a, inst in rows:
        t1 = t0 + int(nf[a])
        if t1 > n_steps:
            continue
        given = any(h["attacker"] == k and h["inst"] == inst for h in hits)
        recv = any(h["victim"] == k and t0 <= h["frame"] < t1 for h in hits)
        fell = any(e["player"] == k and t0 <= int(round(e["t"] * 30)) < t1 for e in falls)
        X.append(x)
        y.append((given, recv, fell))
        acts.append(a)
    return X, y, acts


def _collect_worker(args: tuple) -> dict:
    graph, tracker, seeds, seconds, explore, rl_ckpt, hit_model, future, wid = args
    import torch
    torch.set_num_threads(1)
    from igraph_fight.controller import NPCController
    from igraph_fight.graph import load_graph

    from .bout import PhysicsBout
    from .bout_agents import IGAgent, load_tracker
    from .bout_setup import BoutConfig, BoutSetup
    from .physics_rl import load_rl_agent
    from motion_graph.classify import KINDS
    g = load_graph(graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib, sim_params=g.sim_params())
    trk = load_tracker(tracker)
    rl = load_rl_agent(rl_ckpt, lib)
    nf = np.asarray(lib.n_frames, dtype=np.int64)
    hm = load_hit_model(hit_model) if hit_model else None
    # one fighter per style; its controller also gives the recorded kinematic terms (their raw
    # sim.FT_* columns, the only ones recorded, do not depend on the style)
    fighters = {s: phys_fighter(g, lib, s, 5, hm, future) if hm is not None
                else IGAgent(NPCController(g, lib, style=s, depth=5)) for s in ("infighter", "outboxer")}
    X, Y, A, S, who = [], [], [], [], []
    for seed in seeds:
        style = ("infighter", "outboxer")[seed % 2]
        fa = fighters[style]
        a = _Recorder(fa, fa.controller, explore, len(KINDS))
        if seed % 3 == 2:
            fb = fighters[("outboxer", "infighter")[seed % 2]]
            b = _Recorder(fb, fb.controller, explore, len(KINDS))
        else:
            b = _Recorder(rl, fa.controller, 0.0, len(KINDS))
        bout = PhysicsBout(setup, [a, b], trk, BoutConfig(seconds=seconds, record_qpos=False))
        bout.run(seed=seed)
        for k, rec in enumerate((a, b)):
            x, y, acts = _label(rec.rows, k, bout.hit_events, nf, bout.n_steps, bout.fall_events)
            X += x
            Y += y
            A += acts
            S += [seed] * len(x)
            who += [0 if hasattr(rec.inner, "controller") else 1] * len(x)
        print(f"[worker {wid}] seed {seed}: {len(bout.hit_events)} hits, {len(X)} samples", file=sys.stderr, flush=True)
    for f in fighters.values():
        f.controller.close()
    return {"X": np.array(X), "y": np.array(Y, dtype=np.int8), "action": np.array(A), "seed": np.array(S),
            "rl": np.array(who, dtype=np.int8)}


def collect(graph: str, n_bouts: int, out: str | os.PathLike, seconds: float = 60.0, seed0: int = 1000,
            explore: float = 0.4, workers: int = 2, tracker: str | None = None, rl_ckpt: str | None = None,
            hit_model: str | None = None, future: str = "calibrated") -> dict:
    """Play ``n_bouts`` physics bouts (seeds seed0..) with recorders and write the samples to
    ``out`` (npz: X, y, action, seed, rl). Bouts by seed: IG (infighter on even seeds, outboxer
    on odd) against the RL baseline, every third seed against the other IG style instead. With
    ``hit_model`` the IG fighters are phys_fighter(..., future) agents using it (a further round of
    data from the states the calibrated fighter visits)."""
    seeds = list(range(seed0, seed0 + n_bouts))
    parts = [seeds[i::workers] for i in range(workers)]
    jobs = [(graph, tracker, p, seconds, explore, rl_ckpt, hit_model, future, i) for i, p in enumerate(parts) if p]
    if len(jobs) == 1:
        res = [_collect_worker(jobs[0])]
    else:
        with mp.get_context("spawn").Pool(len(jobs)) as pool:      # no fork under running thread pools
            res = pool.map(_collect_worker, jobs)
    data = {k: np.concatenate([r[k] for r in res if len(r[k])]) for k in ("X", "y", "action", "seed", "rl")}
    meta = {"n_bouts": n_bouts, "seconds": seconds, "seed0": seed0, "explore": explore, "graph": str(graph),
            "hit_model": str(hit_model) if hit_model else None, "future": future if hit_model else None}
    from motion_graph.atomic import atomic_write_bytes
    import io
    buf = io.BytesIO()
    np.savez_compressed(buf, meta=json.dumps(meta), **data)
    atomic_write_bytes(Path(out), buf.getvalue())
    return {"samples": int(len(data["X"])), "given": int(data["y"][:, 0].sum()), "received": int(data["y"][:, 1].sum()),
            "fell": int(data["y"][:, 2].sum()),
            **meta}


# ----------------------------------------------------------------------------------------------
# training and report


def _auc(p: np.ndarray, y: np.ndarray) -> float:
    """Area under the ROC curve (rank statistic); nan if one class is missing."""
    y = y.astype(bool)
    n1, n0 = int(y.sum()), int((~y).sum())
    if n1 == 0 or n0 == 0:
        return float("nan")
    from scipy.stats import rankdata
    r = rankdata(p)
    return float((r[y].sum() - n1 * (n1 + 1) / 2) / (n1 * n0))


def _reliability(p: np.ndarray, y: np.ndarray, edges=(0, .01, .02, .05, .1, .2, .4, 1.0)) -> list[dict]:
    """Held-out predictions binned by predicted probability: mean predicted, observed rate, count."""
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (p >= lo) & (p < hi if hi < 1 else p <= hi)
        if m.any():
            out.append({"lo": lo, "hi": hi, "n": int(m.sum()), "p_mean": float(p[m].mean()), "rate": float(y[m].mean())})
    return out


def plot_report(report: dict, path: str | os.PathLike) -> None:
    """Reliability diagram of the held-out report (predicted vs observed rate per bin, marker
    area ~ samples; the kinematic prediction's two rates as squares)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, len(report), figsize=(5 * len(report), 4.2), squeeze=False)
    for ax, (name, r) in zip(axes[0], report.items()):
        rel = r["reliability"]
        x = [b["p_mean"] for b in rel]
        n_all = sum(b["n"] for b in rel)
        d = np.linspace(0, 1, 400)
        ax.plot(d, d, color="0.7", lw=1)
        ax.scatter(x, [b["rate"] for b in rel], s=[10 + 200 * b["n"] / n_all for b in rel],
                   label="hit model (held-out bins, area ~ samples)")
        ax.plot(x, [b["rate"] for b in rel], lw=1)
        for lab, v in (("kinematic: predicts a hit", r["rate_when_kinematic_predicts"]),
                       ("kinematic: predicts none", r["rate_otherwise"])):
            if v is not None:
                ax.scatter([1.0 if "a hit" in lab else 0.0], [v], marker="s", s=40, label=f"{lab} ({v:.2f})")
        for axis in (ax.set_xscale, ax.set_yscale):
            axis("symlog", linthresh=0.01)
        ax.set_xlim(0, 1.05)
        ax.set_ylim(0, 1.05)
        ax.set_xlabel("predicted probability")
        ax.set_ylabel("observed rate")
        ax.set_title(f"{name}: AUC {r['auc_model']:.2f} (kinematic {r['auc_kinematic']:.2f}), n={r['held_out_samples']}")
        ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    from motion_graph.atomic import atomic_write
    atomic_write(Path(path), lambda fh: fig.savefig(fh, format="png", dpi=100))
    plt.close(fig)


def load_data(path: str | os.PathLike) -> dict:
    """Samples written by ``collect`` (a clear error for anything else)."""
    try:
        z = np.load(path, allow_pickle=False)
        d = {k: z[k] for k in ("X", "y", "action", "seed", "rl")}
        d["meta"] = json.loads(str(z["meta"]))
    except (OSError, KeyError, ValueError) as e:
        raise ValueError(f"{path}: not hit-model samples from `python -m tracker.hit_model collect` ({e})") from None
    return d


def train(data: dict, config: HitModelConfig = HitModelConfig(), n_actions: int | None = None,
          log=print) -> tuple[HitModel, dict]:
    """Fit the model on the bouts not held out (by seed); report log loss, AUC and calibration of
    the held-out bouts beside the kinematic prediction's (sim.FT_DMG_GIVEN / _RECEIVED > 0)."""
    import torch
    from motion_graph.classify import KINDS
    torch.manual_seed(config.seed)
    X, y, seeds = data["X"].astype(np.float32), data["y"][:, :2].astype(np.float32), data["seed"]
    useed = np.unique(seeds)
    rng = np.random.default_rng(config.seed)
    held = rng.choice(useed, size=max(1, int(round(config.holdout * len(useed)))), replace=False) \
        if config.holdout > 0 else np.array([], dtype=useed.dtype)
    te = np.isin(seeds, held)
    tr = ~te
    mean = X[tr].mean(0)
    std = X[tr].std(0) + 1e-3
    net = _mlp(X.shape[1], tuple(config.hidden))
    opt = torch.optim.Adam(net.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    Xt = torch.from_numpy((X[tr] - mean) / std)
    yt = torch.from_numpy(y[tr])
    lossf = torch.nn.BCEWithLogitsLoss()
    g = torch.Generator().manual_seed(config.seed)
    from tqdm import tqdm
    for _ in tqdm(range(config.epochs), desc="hit model", unit="epoch", disable=None):
        perm = torch.randperm(len(Xt), generator=g)
        for i in range(0, len(Xt), config.batch):
            b = perm[i:i + config.batch]
            opt.zero_grad()
            loss = lossf(net(Xt[b]), yt[b])
            loss.backward()
            opt.step()
    net.eval()
    n_act = int(n_actions if n_actions is not None else X.shape[1] - len(_FT_USED) - 4 - len(KINDS) - N_PHYS)
    meta = {"n_in": int(X.shape[1]), "hidden": list(config.hidden), "n_actions": n_act, "n_kinds": len(KINDS),
            "config": asdict(config), "data": data.get("meta", {}), "samples": int(len(X)),
            "train_samples": int(tr.sum()), "held_out_seeds": [int(s) for s in held]}
    model = HitModel(net, mean, std, meta)
    # per action: decisions and landed with / without a kinematic prediction (all samples)
    act = data["action"].astype(np.int64)
    kin = X[:, n_act + _FT_USED.index(5)] > 0
    ar = np.zeros((n_act, 4))
    for cols, m in (((0, 1), kin), ((2, 3), ~kin)):
        np.add.at(ar[:, cols[0]], act[m], 1.0)
        np.add.at(ar[:, cols[1]], act[m], y[m, 0])
    meta["action_rates"] = ar.tolist()
    report = {}
    if te.any():
        p = model.predict(X[te])
        ft_given = X[te][:, n_act + _FT_USED.index(5)]
        ft_recv = X[te][:, n_act + _FT_USED.index(6)]
        for j, (name, kin) in enumerate((("given", ft_given), ("received", ft_recv))):
            yy = y[te][:, j]
            pp = np.clip(p[:, j], 1e-6, 1 - 1e-6)
            base = float(yy[...].mean()) if len(yy) else float("nan")
            kin_pos = kin > 0
            report[name] = {
                "held_out_samples": int(te.sum()), "positives": int(yy.sum()),
                "log_loss": float(-(yy * np.log(pp) + (1 - yy) * np.log(1 - pp)).mean()),
                "log_loss_base_rate": float(-(yy * np.log(base) + (1 - yy) * np.log(1 - base)).mean()) if 0 < base < 1 else None,
                "auc_model": _auc(p[:, j], yy), "auc_kinematic": _auc(kin, yy),
                "kinematic_predicts": int(kin_pos.sum()),
                "rate_when_kinematic_predicts": float(yy[kin_pos].mean()) if kin_pos.any() else None,
                "rate_otherwise": float(yy[~kin_pos].mean()) if (~kin_pos).any() else None,
                "mean_p_model": float(p[:, j].mean()), "rate": base,
                "reliability": _reliability(p[:, j], yy),
            }
            log(f"{name}: held-out {int(te.sum())} samples, {int(yy.sum())} positive; AUC model "
                f"{report[name]['auc_model']:.3f} vs kinematic {report[name]['auc_kinematic']:.3f}; log loss "
                f"{report[name]['log_loss']:.4f} (base rate {report[name]['log_loss_base_rate']})")
    model.meta["report"] = report
    return model, report


def kind_table(data: dict, library) -> list[dict]:
    """Per action kind over collected samples: decisions, mean duration (s), share that landed a
    hit, share hit while playing it, share with a fall in its span and falls per minute of its
    time (the fall column needs data recorded with it)."""
    a = data["action"].astype(np.int64)
    y = data["y"]
    dur = np.asarray(library.n_frames, dtype=np.float64)[a] / 30.0
    labs = np.array([library.labels[i] for i in a])
    out = []
    for k in sorted(set(labs.tolist())):
        m = labs == k
        row = {"kind": k, "n": int(m.sum()), "mean_s": float(dur[m].mean()), "given": float(y[m, 0].mean()),
               "received": float(y[m, 1].mean())}
        if y.shape[1] > 2:
            row["fell"] = float(y[m, 2].mean())
            row["falls_per_min"] = float(60.0 * y[m, 2].sum() / dur[m].sum())
        out.append(row)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tracker.hit_model", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("collect", help="play exploring physics bouts and write hit samples")
    c.add_argument("--graph", required=True)
    c.add_argument("--bouts", type=int, default=200)
    c.add_argument("--seconds", type=float, default=60.0)
    c.add_argument("--seed0", type=int, default=1000)
    c.add_argument("--explore", type=float, default=0.4)
    c.add_argument("--workers", type=int, default=2)
    c.add_argument("--tracker", default=None)
    c.add_argument("--rl", default=None)
    c.add_argument("--hit-model", default=None, help="IG fighters use this hit model (a further data round)")
    c.add_argument("--future", default="calibrated", choices=FUTURES)
    c.add_argument("--out", required=True)
    k = sub.add_parser("kinds", help="per action kind: landed, hit while playing, falls (collected samples)")
    k.add_argument("--data", required=True, nargs="+")
    k.add_argument("--graph", required=True, help="the graph whose library the samples were collected on")
    t = sub.add_parser("train", help="fit the hit model on collected samples")
    t.add_argument("--data", required=True, nargs="+")
    t.add_argument("--out", required=True)
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="HitModelConfig field")
    args = ap.parse_args(argv)
    if args.cmd == "collect":
        r = collect(args.graph, args.bouts, args.out, args.seconds, args.seed0, args.explore, args.workers,
                    args.tracker, args.rl, args.hit_model, args.future)
        print(json.dumps(r, indent=1))
        return 0
    parts = [load_data(p) for p in args.data]
    if args.cmd == "kinds":
        from igraph_fight.graph import load_graph
        lib = load_graph(args.graph).load_library()
        ny = min(d["y"].shape[1] for d in parts)
        data = {"action": np.concatenate([d["action"] for d in parts]),
                "y": np.concatenate([d["y"][:, :ny] for d in parts])}
        for r in kind_table(data, lib):
            print(f"{r['kind']:>13}: {r['n']:6d} decisions, {r['mean_s']:.2f} s, landed {r['given']:.3f}, hit while "
                  f"playing {r['received']:.3f}" + (f", fall in span {r['fell']:.2f}, {r['falls_per_min']:.1f} falls per "
                                                      "minute of it" if "fell" in r else ""))
        return 0
    ny = min(d["y"].shape[1] for d in parts)          # early files have no fall column
    for d in parts:
        d["y"] = d["y"][:, :ny]
    data = {k: np.concatenate([d[k] for d in parts]) for k in ("X", "y", "action", "seed", "rl")}
    data["meta"] = [d["meta"] for d in parts]
    from .overrides import parse_config_overrides
    try:
        cfg = HitModelConfig(**parse_config_overrides(args.set, HitModelConfig))
    except ValueError as exc:
        ap.error(str(exc))
    model, report = train(data, cfg)
    model.save(args.out)
    if report:
        plot_report(report, f"{args.out}.png")
    print(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
