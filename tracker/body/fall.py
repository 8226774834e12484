"""The one definition of a fall, used by the environment, the evaluation and the tests.

A fighter has fallen when, at a control step:
- a collision geom of the fighter that is not a foot or toe geom touches the floor (knee, hand,
  pelvis, torso, head on the canvas), or
- its pelvis is more than ``pelvis_drop_m`` below the reference pelvis (a collapse without a
  touch, e.g. sitting into a deep crouch the reference does not have).
The check runs at the control rate (30 Hz by default): a touch shorter than one control step may
go unseen; falls persist, so this does not change whether a run falls, only by < 33 ms when.
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tracker.body.humanoid import BodyMap

#: Default pelvis drop (metres below the reference pelvis) that counts as a fall.
PELVIS_DROP_M = 0.35


@dataclass(frozen=True)
class FallConfig:
    pelvis_drop_m: float = PELVIS_DROP_M
    floor_touch: bool = True


def fall_geom_mask(model: mujoco.MjModel, fighter: BodyMap) -> np.ndarray:
    """(ngeom,) True for the fighter's non-foot collision geoms."""
    mask = np.zeros(model.ngeom, bool)
    mask[fighter.fall_geoms] = True
    return mask


def detect_fall(data: mujoco.MjData, floor_geom: int, fall_mask: np.ndarray, pelvis_z: float,
                ref_pelvis_z: float, config: FallConfig = FallConfig()) -> str | None:
    """Why the fighter has fallen ("floor_contact" or "pelvis_low"), or None.

    Args:
        data: the simulation state (after mj_step: contacts are current).
        floor_geom: geom id of the floor.
        fall_mask: fall_geom_mask(model, fighter).
        pelvis_z, ref_pelvis_z: pelvis height (metres) of the simulation and of the reference.
    """
    if pelvis_z < ref_pelvis_z - config.pelvis_drop_m:
        return "pelvis_low"
    n = data.ncon
    if config.floor_touch and n:
        g = data.contact.geom[:n]
        a, b = g[:, 0], g[:, 1]
        hit = ((a == floor_geom) & fall_mask[b]) | ((b == floor_geom) & fall_mask[a])
        if hit.any():
            return "floor_contact"
    return None
