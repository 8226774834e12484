#!/bin/bash
# A large evaluation of the shipped planner fighters (STYLE+phys) against the physics RL baseline on
# a machine with many cores (on a lent GPU machine's 16 CPU cores, 384 bouts in
# 382 s; tracker/BOUTS.md, last section). Run from the repository root; the machine needs Python
# with numpy, numba, scipy, torch, tqdm and matplotlib; mujoco can travel as wheels in .whl/
# (INSTALL=1 installs them: `pip download --no-deps --only-binary=:all: --python-version 3.12
# --platform manylinux_2_28_x86_64 -d .whl mujoco==4.0.0 mujoco-core==4.0.0 mujoco-studio==4.0.0
# glfw pyopengl`), the mocap in .devdata/boxing (the graph is built there unless GRAPH is given).
# Env: OUT (results), BOUTS (per style per chunk), WORKERS, BUDGET_S (no new chunk after this many
# seconds), GRAPH, PY, TRACKER (default the shipped policy; e.g. search:16,45:early, fifteenth
# session), BOUT_SECONDS (bout length, 60), SEED (first chunk's first seed, 10000), CHUNKS (at most, 6),
# GRAPH_WORKERS (threads of the graph build there, 16), HIT_MODEL (the IG fighters' first ply: 'default'
# the shipped hit model, STYLE+phys; 'none' the policy table), EVAL_TIMEOUT (seconds a chunk may run,
# 0 for no limit: a cut chunk keeps the bouts its workers logged in eval_<style>.log). Each chunk writes c<N>_<style>.json
# (the physics_rl eval format); the end prints the pooled mean per style.
set -u
PY=${PY:-python3}
OUT=${OUT:-/tmp/devout}; mkdir -p "$OUT"
BOUTS=${BOUTS:-64}; WORKERS=${WORKERS:-16}; BUDGET_S=${BUDGET_S:-330}; GRAPH=${GRAPH:-}
TRACKER=${TRACKER:-tracker/checkpoints/boxing_cmu13.pt}; SECONDS_BOUT=${BOUT_SECONDS:-60}; SEED=${SEED:-10000}
CHUNKS=${CHUNKS:-6}; GRAPH_WORKERS=${GRAPH_WORKERS:-16}; HIT_MODEL=${HIT_MODEL:-default}
HM="--hit-model"; [ "$HIT_MODEL" = none ] && HM=""; [ "$HIT_MODEL" != none ] && [ "$HIT_MODEL" != default ] && HM="--hit-model $HIT_MODEL"
source benchmarks/device_setup.sh
T0=$(date +%s)
for c in $(seq 0 $((CHUNKS - 1))); do
  [ $(( $(date +%s) - T0 )) -gt "$BUDGET_S" ] && break
  t1=$(date +%s)
  # the two styles side by side, half the workers each (a style's bouts are one pool)
  for st in infighter outboxer; do
    timeout ${EVAL_TIMEOUT:-0} $PY -m tracker.physics_rl eval --graph $GRAPH --tracker "$TRACKER" --styles $st --seconds $SECONDS_BOUT \
      --bouts $BOUTS --seed0 $((SEED + BOUTS * c)) $HM --workers $((WORKERS / 2)) --out "$OUT/c${c}_$st.json" \
      >> "$OUT/eval_$st.log" 2>&1 &
  done
  wait || true
  for st in infighter outboxer; do [ -s "$OUT/c${c}_$st.json" ] || { tail -30 "$OUT/eval_$st.log"; exit 1; }; done
  echo "chunk $c: $(( $(date +%s) - t1 )) s"
done
$PY - "$OUT" <<'PY'
import json, sys, glob, numpy as np
for st in ("infighter", "outboxer"):
    rows = [r for f in sorted(glob.glob(sys.argv[1] + "/c*.json")) for r in json.load(open(f))["styles"].get(st, {}).get("bouts", [])]
    sc = np.array([r["score"] for r in rows])
    if len(sc): print(st, len(sc), "bouts, mean", round(sc.mean(), 3), "+-", round(1.96 * sc.std(ddof=1) / np.sqrt(len(sc)), 3))
PY
