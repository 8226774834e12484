"""The generated MuJoCo fighter: builds and steps for every shared skeleton, masses, collision
filtering, semantic geoms, fist contacts reported by target."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np
import pytest

from motion_graph.io import load_motion
from tracker.body.fighter_contacts import fighter_contacts
from tracker.body.humanoid import EFFECTOR_LABELS, TARGET_LABELS, ModelOptions, build_fighter_scene
from tracker.track.reference import build_reference, placement_transform
from tracker.body.spec import fighter_spec

#: One file per distinct skeleton in ../shared/mocap (CMU BVH 13 and 135, CMU ASF 13 and 135, Bandai).
SKELETON_FILES = ("cmu/boxing/13_18.bvh", "cmu/martial_arts/135_06.bvh", "cmu/asf_amc/13_18.amc",
                  "cmu/asf_amc/135_06.amc", "bandai_namco/dataset-1_punch_normal_001.bvh")


@lru_cache(maxsize=None)
def _clip(root: str, rel: str):
    m = load_motion(Path(root) / rel)
    return m.slice(0, min(m.n_frames, int(4 * m.fps)))


def _warnings(d: mujoco.MjData) -> dict[str, int]:
    return {mujoco.mjtWarning(i).name: int(d.warning[i].number) for i in range(len(d.warning)) if d.warning[i].number}


@pytest.mark.realdata
@pytest.mark.parametrize("rel", SKELETON_FILES)
def test_builds_and_steps_without_warnings_for_every_shared_skeleton(mocap_root, rel):
    m = _clip(str(mocap_root), rel)
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, 2)
    f0, f1 = scene.fighters
    assert scene.model.nu == f0.n_act + f1.n_act
    assert len(f0.dof_joints) >= 16
    # Every fighter has the parts contacts are scored on, and feet that are distinct from them.
    for lab in EFFECTOR_LABELS + TARGET_LABELS + ("l_foot", "r_foot"):
        assert len(f0.geom_label.get(lab, [])) >= 1, lab
    # Two fighters a metre apart, each posed on its reference, PD held for 0.5 s.
    refs = [build_reference(m, scene, k, fps=30.0, placement=placement_transform(dx=1.2 * k)) for k in range(2)]
    d = mujoco.MjData(scene.model)
    for k, f in enumerate(scene.fighters):
        d.qpos[f.qpos_slice] = refs[k].qpos[0]
        d.ctrl[f.ctrl_slice] = refs[k].ctrl[0]
    mujoco.mj_forward(scene.model, d)
    mujoco.mj_step(scene.model, d, nstep=120)
    assert np.all(np.isfinite(d.qpos))
    assert _warnings(d) == {}
    # It stands for that long: pelvis still well above the floor.
    for f in scene.fighters:
        assert d.xpos[f.pelvis_body, 2] > 0.5


@pytest.mark.realdata
def test_mass_feet_and_collision_filtering(mocap_root):
    m = _clip(str(mocap_root), "cmu/boxing/13_18.bvh")
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, 2)
    model = scene.model
    for f in scene.fighters:
        mass = float(model.body_subtreemass[f.pelvis_body])
        assert 69.0 < mass < 71.0
        # Feet stand on contact spheres; the ball of the foot sits on the toe's parent (foot) body
        # and toe-tip spheres on the toe body, so the fighter can rise onto the balls of the feet.
        toe_bodies = {int(model.geom_bodyid[g]) for g in f.geom_label["l_foot"]}
        assert len(toe_bodies) == 2
    a, b = scene.fighters
    ga, gb = a.fall_geoms[0], b.fall_geoms[0]
    # No self-collision; fighters collide with each other and with the floor.
    def collide(g1, g2):
        return bool((model.geom_contype[g1] & model.geom_conaffinity[g2]) or
                    (model.geom_contype[g2] & model.geom_conaffinity[g1]))
    assert not collide(ga, a.fall_geoms[1])
    assert collide(ga, gb)
    assert collide(ga, scene.floor_geom) and collide(gb, scene.floor_geom)


@pytest.mark.realdata
def test_model_from_skeleton_alone(mocap_root):
    m = _clip(str(mocap_root), "cmu/boxing/13_18.bvh")
    spec = fighter_spec(m.skeleton)          # no calibration motion: identity rest, default feet
    scene = build_fighter_scene(spec, 1, ModelOptions(joint_type="hinge3"))
    assert scene.fighters[0].joint_type == "hinge3"
    assert scene.model.nu == scene.fighters[0].n_act


@pytest.mark.realdata
def test_fist_contacts_are_reported_by_target(mocap_root):
    m = _clip(str(mocap_root), "cmu/boxing/13_18.bvh")
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, 2)
    model, d = scene.model, mujoco.MjData(scene.model)
    ref = build_reference(m, scene, 0, fps=30.0)
    a, b = scene.fighters
    for f in (a, b):
        d.qpos[f.qpos_slice] = ref.qpos[0]
    # Fighter 1 upside down (180 degrees about world x), its head resting 2 cm deep on fighter 0's
    # right fist from above: the only contacts are on fighter 1's head.
    flip = np.array([0.0, 1.0, 0.0, 0.0])
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, flip, d.qpos[b.qpos_adr + 3:b.qpos_adr + 7].copy())
    d.qpos[b.qpos_adr + 3:b.qpos_adr + 7] = q
    mujoco.mj_kinematics(model, d)
    fist = a.geom_label["r_fist"][0]
    head = b.geom_label["head"][0]
    want = d.geom_xpos[fist] + np.array([0.0, 0.0, model.geom_size[fist, 0] + model.geom_size[head, 0] - 0.02])
    d.qpos[b.qpos_adr:b.qpos_adr + 3] += want - d.geom_xpos[head]
    mujoco.mj_forward(model, d)
    hits = fighter_contacts(scene, d)
    pairs = {(c.attacker, c.effector, c.defender, c.target) for c in hits}
    assert (0, "r_fist", 1, "head") in pairs
    top = [c for c in hits if c.target == "head"][0]
    assert top.force_n > 0 and top.is_hit_target
    assert fighter_contacts(scene, d, min_force_n=1e9) == []
