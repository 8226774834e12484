"""Physically measured hit odds for the Interaction Graph fighter's first ply.

In physics bouts the planner's kinematic hit predictions hold for a minority of its planned hits
(about a third under the assisted tracker, 12% under the legacy one: docs/tracker.md): the bodies
are not where each reference's displacement puts them. This
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
(the first ply alone). Measured against the physics RL baseline in research/notes/BOUTS.md.

Data come from bouts with exploration (a share of each IG fighter's decisions uniform over its
menu) against the RL baseline and other IG fighters, on seeds apart from the evaluation's; the
RL fighter's own decisions are samples too. Labels: ``given`` = the action instance produced a
realised hit (tracker.bouts.judging); ``received`` = a realised hit on the fighter between its decision
instant and the action's nominal end (``fell``, a fall in that span, is recorded, not modelled).
Named approximations: the odds are those of the collection's opponents, exploration rate and
tracking policy, not of every opponent or tracker; the later plies' calibration is one rate per head, not per state.

    igraph-fight tracker hit-model collect --graph G.igz --bouts 240 --explore 0.4 --out r1.npz [--workers 2]
    igraph-fight tracker hit-model collect --graph G.igz --bouts 160 --seed0 2000 --explore 0.25 --hit-model M1.pt --future kinematic --out r2.npz
    igraph-fight tracker hit-model train --data r1.npz r2.npz ... --out tracker/checkpoints/hit_model_cmu13.pt   # + .png reliability plot
    igraph-fight tracker hit-model kinds --data r1.npz ... --graph G.igz      # per action kind: landed, hit, falls
    igraph-fight fight --physics --graph G.igz --a infighter+phys --b rl ...      # the fighter; +phys:MODEL for another model
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from igraph_fight.agents.ig import IGAgent

DEFAULT_HIT_MODEL = Path(__file__).resolve().parent.parent / "checkpoints" / "hit_model_cmu13.pt"
#: the model file's format and version (igraph_fight.checkpoint; tracker/checkpoints/README.md)
HIT_MODEL_FORMAT = "igraph-fight/hit-model"
HIT_MODEL_VERSION = 1

#: kinematic features taken from NPCController.menu_terms' raw sim.FT_* columns
FT_USED = (0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 11, 12, 14, 15)
N_PHYS = 14      # PhysicsBout.features


def feature_vector(obs, phys: np.ndarray, mt: np.ndarray, kind_other: int, n_actions: int,
                   n_kinds: int) -> np.ndarray:
    """Model inputs for each row of ``mt`` (NPCController.menu_terms, one row per candidate
    action): action one-hot, the row's kinematic features, the coupled state (r m, |angles| rad,
    the opponent's frame at 30 fps in s), the opponent's action kind one-hot and the physical
    features. Shape (rows, n_actions + 14 + 4 + n_kinds + 14)."""
    from igraph_fight.controller import MT_ACTION, MT_FT
    n = mt.shape[0]
    X = np.zeros((n, n_actions + len(FT_USED) + 4 + n_kinds + N_PHYS))
    X[np.arange(n), mt[:, MT_ACTION].astype(np.int64)] = 1.0
    c = n_actions
    X[:, c:c + len(FT_USED)] = mt[:, [MT_FT + i for i in FT_USED]]
    c += len(FT_USED)
    X[:, c:c + 4] = [obs.r, abs(obs.theta_self), abs(obs.theta_other), obs.f_other / 30.0]
    c += 4
    if 0 <= kind_other < n_kinds:
        X[:, c + kind_other] = 1.0
    c += n_kinds
    X[:, c:c + N_PHYS] = np.asarray(phys, dtype=np.float64)[:N_PHYS]
    return X


# ----------------------------------------------------------------------------------------------
# the model


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
        """Write the model atomically (igraph_fight.checkpoint, HIT_MODEL_FORMAT)."""
        from igraph_fight.checkpoint import save_checkpoint
        ck = {"model": self.net.state_dict(), "mean": self.mean, "std": self.std, "meta": self.meta}
        save_checkpoint(path, ck, HIT_MODEL_FORMAT, HIT_MODEL_VERSION)


def hit_network(n_in: int, hidden: tuple):
    """The model's MLP: tanh hidden layers, two logits (given, received)."""
    import torch.nn as nn
    layers, d = [], n_in
    for h in hidden:
        layers += [nn.Linear(d, h), nn.Tanh()]
        d = h
    layers.append(nn.Linear(d, 2))
    return nn.Sequential(*layers)


def load_hit_model(path: str | os.PathLike | None = None) -> HitModel:
    """A trained hit model (default: the shipped tracker/checkpoints/hit_model_cmu13.pt)."""
    from igraph_fight.checkpoint import CheckpointError, load_checkpoint
    p = Path(path) if path else DEFAULT_HIT_MODEL
    if not p.is_file():
        raise FileNotFoundError(f"no hit model at {p} (train one: igraph-fight tracker hit-model collect ... ; train ...)")
    ck = load_checkpoint(p, HIT_MODEL_FORMAT, (HIT_MODEL_VERSION,), what="hit model")
    try:
        net = hit_network(int(ck["meta"]["n_in"]), tuple(ck["meta"]["hidden"]))
        net.load_state_dict(ck["model"])
    except Exception as e:  # a clear error naming the file, not a traceback from inside torch
        raise CheckpointError(str(p), f"not a hit model checkpoint ({type(e).__name__}: "
                                      f"{str(e).strip().splitlines()[0] if str(e).strip() else ''})") from None
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


class PhysIGAgent(IGAgent):
    """An IG fighter (igraph_fight.agents.ig.IGAgent, no snapping) whose first ply scores every
    legal action with the physically measured hit odds in place of the kinematic damage terms
    (module docstring), under ``style`` (the controller's style by default). The later plies are
    the controller's policy values: ``future`` says what the controller's table is ("kinematic":
    the style's own; "calibrated": calibrated_style's, built by phys_fighter; "none": the values
    are ignored). Counts decisions and off-graph decisions (zeroed by reset)."""

    def __init__(self, controller, model: HitModel, name: str | None = None, style=None,
                 future: str = "kinematic") -> None:
        if future not in FUTURES:
            raise ValueError(f"future must be one of {', '.join(FUTURES)}, not {future!r}")
        lib = controller.library
        if int(model.meta["n_actions"]) != lib.n_actions:
            raise ValueError(f"hit model was trained on {model.meta['n_actions']} actions, the library has "
                             f"{lib.n_actions}")
        super().__init__(controller, name=name or f"{(style or controller.style_def).name}({controller.depth}, phys)",
                         snap=False)
        self.model = model
        self.style = style
        self.future = future
        self.value_scale = 0.0 if future == "none" else 1.0
        self.kinds = np.asarray(controller.action_kinds, dtype=np.int64)
        self.n_kinds = int(model.meta["n_kinds"])
        self._pref = (None, None)      # (style, its kind preferences)

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

    def step(self, ctx, player: int) -> int:
        self.decisions += 1
        self.off_graph += int(self.controller.locate(ctx.obs)[2])
        return self.peek(ctx, player)

    def peek(self, ctx, player: int) -> int:
        """What step() answers for ``ctx``, without counting it (it is deterministic)."""
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
