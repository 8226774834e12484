"""Contacts between fighters, reported by body part: which fist touched which target, how hard.

``fighter_contacts(scene, data)`` lists the current contacts between an effector geom of one
fighter (by default the fists) and a geom of another fighter, labelled with the target part
(head, chest, belly, or any other segment label such as l_upper_arm), with the normal force in
newtons. Issue 8 (physics bouts) counts a hit when the target is in TARGET_LABELS and the force
is above a threshold (``min_force_n``).
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tracker.body.humanoid import EFFECTOR_LABELS, TARGET_LABELS, FighterScene


@dataclass(frozen=True)
class FighterContact:
    """One contact: ``attacker``'s ``effector`` geom against ``defender``'s ``target`` geom.

    Attributes:
        force_n: normal contact force (N).
        pos: (3,) contact point, world (MuJoCo, Z up, metres).
    """

    attacker: int
    effector: str
    defender: int
    target: str
    force_n: float
    pos: np.ndarray

    @property
    def is_hit_target(self) -> bool:
        return self.target in TARGET_LABELS


def geom_table(scene: FighterScene) -> tuple[np.ndarray, list[str]]:
    """(ngeom,) fighter index per geom (-1 for the floor and non-fighter geoms) and the label per geom."""
    cached = getattr(scene, "_geom_table", None)
    if cached is not None:
        return cached
    m = scene.model
    owner = np.full(m.ngeom, -1)
    label = [""] * m.ngeom
    for f in scene.fighters:
        for lab, ids in f.geom_label.items():
            for g in ids:
                owner[g] = f.index
                label[g] = lab
    scene._geom_table = (owner, label)
    return owner, label


def fighter_contacts(scene: FighterScene, data: mujoco.MjData, min_force_n: float = 0.0,
                     effectors: tuple[str, ...] = EFFECTOR_LABELS) -> list[FighterContact]:
    """Current effector-on-opponent contacts (see module doc), strongest first."""
    owner, label = geom_table(scene)
    out: list[FighterContact] = []
    n = data.ncon
    if n == 0:
        return out
    g = data.contact.geom[:n]
    oa, ob = owner[g[:, 0]], owner[g[:, 1]]
    cand = np.nonzero((oa >= 0) & (ob >= 0) & (oa != ob))[0]
    f6 = np.zeros(6)
    for i in cand:
        g1, g2 = int(g[i, 0]), int(g[i, 1])
        for ga, gb in ((g1, g2), (g2, g1)):
            if label[ga] in effectors:
                mujoco.mj_contactForce(scene.model, data, int(i), f6)
                force = abs(float(f6[0]))
                if force >= min_force_n:
                    out.append(FighterContact(int(owner[ga]), label[ga], int(owner[gb]), label[gb], force,
                                              data.contact.pos[i].copy()))
    out.sort(key=lambda c: -c.force_n)
    return out
