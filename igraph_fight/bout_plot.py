"""The figure shared by the kinematic and the physics bout plots: distance over time above
cumulative hits (igraph_fight.match and tracker.bouts.media)."""
from __future__ import annotations

from pathlib import Path


def distance_and_hits_figure(t: list[float], distance: list[float], ylabel: str, title: str,
                             height: float = 6.0):
    """(fig, ax_distance, ax_hits): distance over time (s) plotted on top, the hits axis below."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(12, height), sharex=True)
    ax0.plot(t, distance, color="#444", lw=1)
    ax0.set_ylabel(ylabel)
    ax0.set_title(title)
    ax1.set_ylabel("cumulative hits")
    return fig, ax0, ax1


def cumulative_steps(ax, times: list[float], seconds: float, **kw) -> None:
    """A step curve counting the events at ``times`` (s) from 0 to the bout's end."""
    ax.step([0.0] + list(times) + [seconds], list(range(len(times) + 1)) + [len(times)], where="post", **kw)


def save_figure(fig, path: str | Path) -> None:
    """Write the PNG atomically and close the figure."""
    import matplotlib.pyplot as plt

    from motion_graph.atomic import atomic_write
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=80))
    plt.close(fig)
