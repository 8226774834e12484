"""Segmentation timeline plot: foot contacts, quietness, fist reach, cuts and labels."""
from __future__ import annotations

import os

import numpy as np


def plot_timelines(clips: list[dict], path: str | os.PathLike) -> None:
    """One panel group per clip. Each clip dict holds: name, fps, contacts (T, 2), quietness (T,),
    reach (T, 2), cuts (K+1,) source frames, labels (K,) str, strikes (list of Strike)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from motion_graph.atomic import atomic_write
    from motion_graph.classify import ATTACK_KINDS, DEFENCE_KINDS

    n = len(clips)
    fig, axes = plt.subplots(3 * n, 1, figsize=(18, 4.2 * n), sharex=False,
                             gridspec_kw={"height_ratios": [1, 1.2, 1.2] * n})
    axes = np.atleast_1d(axes)
    colours = {"attack": "#d62728", "defence": "#2ca02c", "move": "#1f77b4", "guard": "#7f7f7f"}
    for i, c in enumerate(clips):
        t = np.arange(len(c["quietness"])) / c["fps"]
        ax0, ax1, ax2 = axes[3 * i:3 * i + 3]
        ax0.fill_between(t, 1.05, 1.45, where=c["contacts"][:, 0], color="#8c564b", step="mid", label="left foot")
        ax0.fill_between(t, 0.55, 0.95, where=c["contacts"][:, 1], color="#e377c2", step="mid", label="right foot")
        ax0.fill_between(t, 0.0, 0.45, where=c["contacts"].all(axis=1), color="k", step="mid", label="double support")
        ax0.set_yticks([])
        ax0.set_title(f"{c['name']}: {len(c['labels'])} actions", loc="left")
        ax0.legend(loc="upper right", ncol=3, fontsize=8)
        ax1.plot(t, c["reach"][:, 0], lw=0.8, label="left fist reach")
        ax1.plot(t, c["reach"][:, 1], lw=0.8, label="right fist reach")
        for s in c["strikes"]:
            ax1.axvspan(s.w0 / c["fps"], s.w1 / c["fps"], color="#d62728", alpha=0.25)
        ax1.set_ylabel("reach / arm")
        ax1.legend(loc="upper right", fontsize=8)
        ax2.plot(t, c["quietness"], lw=0.6, color="#555")
        ax2.set_ylabel("speed sum (m/s)")
        ymax = float(np.percentile(c["quietness"], 99.5))
        for k, (a, b) in enumerate(zip(c["cuts"][:-1], c["cuts"][1:])):
            lab = c["labels"][k]
            group = ("attack" if lab in ATTACK_KINDS else "defence" if lab in DEFENCE_KINDS
                     else "guard" if lab == "guard" else "move")
            ax2.axvspan(a / c["fps"], b / c["fps"], color=colours[group], alpha=0.15)
            ax2.text((a + b) / 2 / c["fps"], ymax * 0.95, lab.replace("_", "\n"), ha="center", va="top", fontsize=7,
                     rotation=0, color=colours[group])
        for x in c["cuts"]:
            for ax in (ax0, ax1, ax2):
                ax.axvline(x / c["fps"], color="k", lw=0.5, alpha=0.6)
        ax2.set_ylim(0, ymax)
        ax2.set_xlabel("time (s)")
        for ax in (ax0, ax1, ax2):
            ax.set_xlim(0, t[-1])
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format=str(path).rsplit(".", 1)[-1] if "." in str(path) else "png",
                                             dpi=70))
    plt.close(fig)
