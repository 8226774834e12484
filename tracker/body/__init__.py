"""The physics fighters' bodies: a fighter calibrated on its mocap skeleton (spec), the MuJoCo model
and ring scene built from it (humanoid), fist-to-target contacts (fighter_contacts), the one fall
definition (fall) and the z-up frame helpers (frames)."""
