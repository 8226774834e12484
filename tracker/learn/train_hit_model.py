"""Data and training of the hit model (tracker.bouts.hit_model): exploring physics bouts recorded
decision by decision (collect), the model fitted on them with a held-out report (train), and a
per-action-kind table of collected samples (kind_table).

    igraph-fight tracker hit-model collect --graph G.igz --bouts 240 --explore 0.4 --out r1.npz [--workers 2]
    igraph-fight tracker hit-model train --data r1.npz r2.npz ... --out tracker/checkpoints/hit_model_cmu13.pt
    igraph-fight tracker hit-model kinds --data r1.npz ... --graph G.igz

Data come from bouts with exploration (a share of each IG fighter's decisions uniform over its
menu) against the RL baseline and other IG fighters, on seeds apart from the evaluation's; the
RL fighter's own decisions are samples too. Labels: ``given`` = the action instance produced a
realised hit (tracker.bouts.judging); ``received`` = a realised hit on the fighter between its
decision instant and the action's nominal end (``fell``, a fall in that span, is recorded, not modelled).
"""
from __future__ import annotations

import json
import multiprocessing as mp
import os
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from tracker.bouts.hit_model import (FT_USED, N_PHYS, HitModel, feature_vector, hit_network, load_hit_model,
                                     phys_fighter)


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

    def reset(self, bout, player: int, rng: np.random.Generator) -> None:
        self.bout, self.k = bout, player
        self.rng = np.random.default_rng(rng.integers(1 << 31))
        self.rows = []
        self.inner.reset(bout, player, rng)

    def step(self, ctx, player: int) -> int:
        a = int(self.inner.step(ctx, player))
        if self.explore > 0 and self.rng.random() < self.explore:
            a = int(self.rng.choice(ctx.menu))
        mt = self.npc.menu_terms(ctx.obs)
        j = int(np.nonzero(mt[:, 0].astype(np.int64) == a)[0][0])
        kinds = self.npc.action_kinds
        x = feature_vector(ctx.obs, ctx.features, mt[j:j + 1], int(kinds[int(ctx.obs.m_other)]),
                           self.npc.library.n_actions, self.n_kinds)[0]
        self.rows.append((x, int(round(ctx.t_s * 30)), a, self.bout.F[ctx.k].n_inst + 1))
        return a


def label_decisions(rows, k: int, hits: list[dict], nf: np.ndarray, n_steps: int, falls: list[dict] = ()):
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


def _ig_fighter(npc):
    from igraph_fight.agents.ig import IGAgent
    return IGAgent(npc, name=f"{npc.style}({npc.depth})", snap=False)


def _collect_worker(args: tuple) -> dict:
    graph, tracker, seeds, seconds, explore, rl_ckpt, hit_model, future, wid = args
    import torch
    torch.set_num_threads(1)
    from igraph_fight.controller import NPCController
    from igraph_fight.graph import load_graph

    from motion_graph.classify import KINDS

    from tracker.bouts.loaders import load_tracker
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.rl_agent import load_rl_agent
    from tracker.bouts.setup import BoutConfig, BoutSetup
    g = load_graph(graph)
    lib = g.load_library()
    trk = load_tracker(tracker)
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), tracker=trk)
    rl = load_rl_agent(rl_ckpt, lib)
    nf = np.asarray(lib.n_frames, dtype=np.int64)
    hm = load_hit_model(hit_model) if hit_model else None
    # one fighter per style; its controller also gives the recorded kinematic terms (their raw
    # sim.FT_* columns, the only ones recorded, do not depend on the style)
    fighters = {s: phys_fighter(g, lib, s, 5, hm, future) if hm is not None
                else _ig_fighter(NPCController(g, lib, style=s, depth=5)) for s in ("infighter", "outboxer")}
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
            x, y, acts = label_decisions(rec.rows, k, bout.hit_events, nf, bout.n_steps, bout.fall_events)
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
        raise ValueError(f"{path}: not hit-model samples from `igraph-fight tracker hit-model collect` ({e})") from None
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
    net = hit_network(X.shape[1], tuple(config.hidden))
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
    n_act = int(n_actions if n_actions is not None else X.shape[1] - len(FT_USED) - 4 - len(KINDS) - N_PHYS)
    meta = {"n_in": int(X.shape[1]), "hidden": list(config.hidden), "n_actions": n_act, "n_kinds": len(KINDS),
            "config": asdict(config), "data": data.get("meta", {}), "samples": int(len(X)),
            "train_samples": int(tr.sum()), "held_out_seeds": [int(s) for s in held]}
    model = HitModel(net, mean, std, meta)
    # per action: decisions and landed with / without a kinematic prediction (all samples)
    act = data["action"].astype(np.int64)
    kin = X[:, n_act + FT_USED.index(5)] > 0
    ar = np.zeros((n_act, 4))
    for cols, m in (((0, 1), kin), ((2, 3), ~kin)):
        np.add.at(ar[:, cols[0]], act[m], 1.0)
        np.add.at(ar[:, cols[1]], act[m], y[m, 0])
    meta["action_rates"] = ar.tolist()
    report = {}
    if te.any():
        p = model.predict(X[te])
        ft_given = X[te][:, n_act + FT_USED.index(5)]
        ft_recv = X[te][:, n_act + FT_USED.index(6)]
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
