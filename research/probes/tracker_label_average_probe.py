"""Do averaged search labels agree, and do they keep the body up? (issue 7, research/notes/TRAINING.md item 0)

The search's single labels (the best or first offset that stays up) from two searches of one
state are nearly orthogonal, so a student learns their mean. An MPPI-style average over many
candidates is the proposed cure. This probe measures it where it matters: at the states where the
plain policy's own 1.5 s rollout falls (the search-fast controller's full searches, tracker
walks of the tuning seed 100). At each such state, two independent sets of N random offsets (the
search's sigmas) are rolled out over the segment + look-ahead; per set:

- p_up: the share of random offsets whose rollout stays up (what one lottery ticket is worth);
- the mean of the offsets that stay up, and the return-weighted mean exp((R - max R) / (tau std R));
- whether each average, played as the offset, stays up itself;
- cosines between the two sets' averages (their agreement), and the averages' norm against a
  single offset's (how much averaging cancels).

    python -m research.probes.tracker_label_average_probe [--walks 4] [--first 0] [--n 128] [--states 25] [--json-out F]
    python -m research.probes.tracker_label_average_probe --n 64 --states 250 --collect F.npz   # (observation, label) pairs
    python -m research.probes.tracker_label_average_probe --first 40 --n 16 --states 40 --proposal F.npz ...  # a ridge proposal played
    python -m research.probes.tracker_label_average_probe --scores A.npz,B.npz C.npz   # held-out fits, no simulation

Prints one JSON line with the totals; --json-out keeps the per-state rows.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


from tracker.track.evaluation import draw_walks, make_setup, run_walk
from tracker.track.policy_net import load_policy
from research.search_controller import FAST_SEARCH, SearchController
from tracker.track.walks import walk_source


def _cos(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    return float(a @ b / (na * nb)) if na > 0 and nb > 0 else float("nan")


class ProbingSearch(SearchController):
    """search-fast, probing the label averages at the first ``max_states`` full searches."""

    def __init__(self, n: int, max_states: int, tau: float, seed: int) -> None:
        super().__init__(load_policy(None), FAST_SEARCH)
        self.n, self.max_states, self.tau = n, max_states, tau
        self.probe_rng = np.random.default_rng(seed)
        self.rows: list[dict] = []

    def _search(self, env, obs):
        full = self.stats["full"]
        st = self._save(env)
        best = super()._search(env, obs)                 # leaves the env as it was
        if self.stats["full"] > full and len(self.rows) < self.max_states:
            self.rows.append(self._probe(env, obs, st))
            self._restore(env, st)
        return best

    def _roll(self, env, obs, st, delta) -> tuple[float, bool]:
        self._restore(env, st)
        ret, kept, _ = self._score(env, obs, delta)
        return ret, kept

    def _sample(self, env, obs, st) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """N random offsets (the search's sigmas) rolled out from st: offsets, returns, stayed up."""
        deltas = self.probe_rng.normal(0.0, 1.0, (self.n, len(self.sig))) * self.sig
        rk = [self._roll(env, obs, st, d) for d in deltas]
        return deltas, np.array([r for r, _ in rk]), np.array([k for _, k in rk])

    def _probe(self, env, obs, st) -> dict:
        sets = []
        for _ in range(2):
            deltas, ret, up = self._sample(env, obs, st)
            w = np.exp((ret - ret.max()) / (self.tau * ret.std() + 1e-12))
            mppi = (w[:, None] * deltas).sum(0) / w.sum()
            mean_up = deltas[up].mean(0) if up.any() else np.zeros(len(self.sig))
            sets.append(dict(p_up=float(up.mean()), mppi=mppi, mean_up=mean_up,
                             single=float(np.linalg.norm(deltas, axis=1).mean()),
                             first_up=deltas[np.argmax(up)] if up.any() else None))
        a, b = sets
        row = dict(t=int(env.t), p_up=[a["p_up"], b["p_up"]],
                   cos_mppi=_cos(a["mppi"], b["mppi"]), cos_mean_up=_cos(a["mean_up"], b["mean_up"]),
                   cos_first_up=_cos(a["first_up"], b["first_up"]) if a["first_up"] is not None
                   and b["first_up"] is not None else float("nan"),
                   norm_mppi=float(np.linalg.norm(a["mppi"]) / a["single"]),
                   norm_mean_up=float(np.linalg.norm(a["mean_up"]) / a["single"]))
        for key in ("mppi", "mean_up"):
            row[f"{key}_stays_up"] = [bool(self._roll(env, obs, st, s[key])[1]) for s in sets]
        return row


class CollectingSearch(ProbingSearch):
    """search-fast, recording at each full search the observation and the mean of the offsets (of
    one set of N) whose rollouts stay up; with ``proposal`` (W, b, mu, sd: a ridge map from the
    standardised observation) also whether the proposed offset stays up there."""

    def __init__(self, n: int, max_states: int, seed: int, proposal=None) -> None:
        super().__init__(n, max_states, 1.0, seed)
        self.proposal = proposal

    def _probe(self, env, obs, st) -> dict:
        row = dict(obs=np.asarray(obs, float).copy())
        if self.proposal is not None:
            W, b, mu, sd = self.proposal
            guess = np.clip(((obs - mu) / sd) @ W + b, -3 * self.sig, 3 * self.sig)
            row["proposal_stays_up"] = bool(self._roll(env, obs, st, guess)[1])
            row["scaled_stays_up"] = bool(self._roll(env, obs, st, 2.0 * guess)[1])
            row["const_stays_up"] = bool(self._roll(env, obs, st, b)[1])      # the mean label, whatever the state
        deltas, _, up = self._sample(env, obs, st)
        row.update(label=deltas[up].mean(0) if up.any() else np.zeros(len(self.sig)), p_up=float(up.mean()))
        return row


def _save_labels(path: str, rows: list[dict]) -> None:
    """The collected (observation, label, p_up) rows as .npz, written atomically."""
    from motion_graph.atomic import atomic_write
    atomic_write(path, lambda fh: np.savez(fh, obs=np.array([r["obs"] for r in rows]),
                                           label=np.array([r["label"] for r in rows]),
                                           p_up=np.array([r["p_up"] for r in rows])))


def _load_labels(files: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Observations and labels of --collect files, the states where some offset stayed up."""
    ds = [np.load(f) for f in files]
    keep = np.concatenate([d["p_up"] > 0 for d in ds])
    return np.concatenate([d["obs"] for d in ds])[keep], np.concatenate([d["label"] for d in ds])[keep]


def _ridge(Z: np.ndarray, Y: np.ndarray, alpha: float) -> tuple[np.ndarray, np.ndarray]:
    """Ridge regression Y ~ Z W + b (b the mean of Y, not penalised)."""
    b = Y.mean(0)
    return np.linalg.solve(Z.T @ Z + alpha * np.eye(Z.shape[1]), Z.T @ (Y - b)), b


def fit_proposal(files: list[str], alphas=(1.0, 10.0, 100.0, 1000.0, 10000.0)):
    """Ridge map standardised observation -> averaged label, alpha by held-out R^2 (the files'
    last fifth of states held out); returns (W, b, mu, sd) refitted on all, and the scores."""
    X, Y = _load_labels(files)
    mu, sd = X.mean(0), X.std(0) + 1e-6
    Z = (X - mu) / sd
    cut = int(0.8 * len(Z))
    scores = {}
    for alpha in alphas:
        W, b = _ridge(Z[:cut], Y[:cut], alpha)
        P = Z[cut:] @ W + b
        r2 = 1.0 - ((Y[cut:] - P) ** 2).sum() / ((Y[cut:] - Y[:cut].mean(0)) ** 2).sum()
        cos = np.mean([_cos(p, y) for p, y in zip(P, Y[cut:])])
        scores[alpha] = (float(r2), float(cos))
    best = max(scores, key=lambda k: scores[k][0])
    W, b = _ridge(Z, Y, best)
    return (W, b, mu, sd), dict(states=len(Z), held_out=len(Z) - cut, alpha=best, scores=scores)


def held_out_scores(train: list[str], test: list[str], seed: int = 0) -> dict:
    """How well the averaged labels of ``test`` (.npz from --collect) are predicted from their
    observations by maps fitted on ``train``: held-out R^2 and mean cosine for ridge regression,
    k nearest neighbours and a one-hidden-layer MLP (early-stopped on 15% of train)."""
    import torch

    Xtr, Ytr = _load_labels(train)
    Xte, Yte = _load_labels(test)
    mu, sd = Xtr.mean(0), Xtr.std(0) + 1e-6
    Ztr, Zte = (Xtr - mu) / sd, (Xte - mu) / sd
    ym, ys = Ytr.mean(0), Ytr.std(0) + 1e-9

    def score(P):
        r2 = 1.0 - ((Yte - P) ** 2).sum() / ((Yte - ym) ** 2).sum()
        return [round(float(r2), 4), round(float(np.mean([_cos(p, y) for p, y in zip(P, Yte)])), 3)]
    out = dict(train=len(Ztr), test=len(Zte))
    for alpha in (1e2, 1e3, 1e4, 1e5):
        W, b = _ridge(Ztr, Ytr, alpha)
        out[f"ridge_{alpha:g}"] = score(Zte @ W + b)
    d2 = (Zte ** 2).sum(1)[:, None] - 2 * Zte @ Ztr.T + (Ztr ** 2).sum(1)[None]
    order = np.argsort(d2, axis=1)
    for k in (5, 20, 50):
        out[f"knn_{k}"] = score(Ytr[order[:, :k]].mean(1))
    torch.manual_seed(seed)
    zt = torch.tensor(Ztr, dtype=torch.float32)
    yt = torch.tensor((Ytr - ym) / ys, dtype=torch.float32)
    cut = int(0.85 * len(zt))
    for wd in (1e-3, 1e-2):
        net = torch.nn.Sequential(torch.nn.Linear(zt.shape[1], 128), torch.nn.Tanh(), torch.nn.Linear(128, yt.shape[1]))
        opt = torch.optim.Adam(net.parameters(), 1e-3, weight_decay=wd)
        best = (np.inf, None, -1)
        for epoch in range(200):
            perm = torch.randperm(cut)
            for i in range(0, cut, 64):
                j = perm[i:i + 64]
                loss = ((net(zt[j]) - yt[j]) ** 2).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
            with torch.no_grad():
                v = float(((net(zt[cut:]) - yt[cut:]) ** 2).mean())
            if v < best[0]:
                best = (v, {k: x.clone() for k, x in net.state_dict().items()}, epoch)
        net.load_state_dict(best[1])
        with torch.no_grad():
            P = net(torch.tensor(Zte, dtype=torch.float32)).numpy() * ys + ym
        out[f"mlp_wd{wd:g}"] = score(P) + [best[2]]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--walks", type=int, default=4)
    ap.add_argument("--first", type=int, default=0, help="skip the seed's first walks")
    ap.add_argument("--seed", type=int, default=100, help="walk seed (100: the tuning seed)")
    ap.add_argument("--n", type=int, default=128, help="random offsets per set (two sets per state)")
    ap.add_argument("--states", type=int, default=25, help="probe at most this many states")
    ap.add_argument("--tau", type=float, default=0.2, help="MPPI temperature, in standard deviations of the returns")
    ap.add_argument("--json-out", default="")
    ap.add_argument("--collect", default="", help="record (observation, averaged label) at full searches into this .npz")
    ap.add_argument("--proposal", nargs="*", default=None,
                    help="fit a ridge proposal on these --collect files and test it at this run's full searches")
    ap.add_argument("--scores", nargs=2, metavar=("TRAIN", "TEST"),
                    help="comma-separated --collect files: held-out R^2 / cosine of ridge, kNN and MLP maps (no simulation)")
    a = ap.parse_args(argv)
    if a.scores:
        print(json.dumps(held_out_scores(a.scores[0].split(","), a.scores[1].split(","))))
        return 0
    setup = make_setup(walk_source(None))
    if a.collect or a.proposal is not None:
        prop, fit = fit_proposal(a.proposal) if a.proposal else (None, None)
        ctrl = CollectingSearch(a.n, a.states, seed=a.seed + a.first, proposal=prop)
        for walk in draw_walks(setup.source, a.first + a.walks, 20, a.seed)[a.first:]:
            if len(ctrl.rows) >= a.states:
                break
            run_walk(setup, ctrl, walk)
            if a.collect and ctrl.rows:               # after every walk, so a long collection can be stopped
                _save_labels(a.collect, ctrl.rows)
        rows = ctrl.rows
        out = dict(states=len(rows), n=a.n, p_up=float(np.mean([r["p_up"] for r in rows])))
        if prop is not None:
            out.update(fit=fit, proposal_stays_up=float(np.mean([r["proposal_stays_up"] for r in rows])),
                       scaled_stays_up=float(np.mean([r["scaled_stays_up"] for r in rows])),
                       const_stays_up=float(np.mean([r["const_stays_up"] for r in rows])))
        print(json.dumps(out))
        return 0
    ctrl = ProbingSearch(a.n, a.states, a.tau, seed=a.seed + a.first)
    for walk in draw_walks(setup.source, a.first + a.walks, 20, a.seed)[a.first:]:
        if len(ctrl.rows) >= a.states:
            break
        run_walk(setup, ctrl, walk)
    rows = ctrl.rows
    if not rows:
        print(json.dumps({"states": 0}))
        return 0

    def mean(key):
        return float(np.nanmean([r[key] for r in rows]))

    def share(key):
        return float(np.mean([x for r in rows for x in r[key]]))
    out = dict(states=len(rows), n=a.n, tau=a.tau, p_up=share("p_up"),
               mppi_stays_up=share("mppi_stays_up"), mean_up_stays_up=share("mean_up_stays_up"),
               cos_mppi=mean("cos_mppi"), cos_mean_up=mean("cos_mean_up"), cos_first_up=mean("cos_first_up"),
               norm_mppi=mean("norm_mppi"), norm_mean_up=mean("norm_mean_up"))
    if a.json_out:
        Path(a.json_out).write_text(json.dumps(dict(out, rows=rows), indent=1))
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
