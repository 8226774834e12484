#!/bin/bash
# Many physics bouts side by side on a machine with many cores, each cut at a wall-clock budget
# (tracker.bout_cli fight --max-wall-s): for trackers far slower than real time (the search tracker
# runs at 0.05-0.1x), a lent machine's cores simulate the first seconds of many bouts at once.
# Run from the repository root. The machine needs Python with numpy, numba, scipy, torch, tqdm and
# matplotlib; mujoco can travel as wheels in .whl/ (INSTALL=1 installs them; see
# benchmarks/device_eval.sh for the pip download line), the mocap in .devdata/boxing (the graph is
# built there unless GRAPH is given; its content hash is printed).
# Env: OUT (results: bouts.tgz with every bout's summary.json and log.jsonl, and table.txt),
# CONFIGS ("NAME=A_SPEC,B_SPEC ..."; e.g. "close=infighter+close,outboxer+close plain=infighter,outboxer";
# a comma before a digit stays inside a spec, as in infighter+close:avoid=7,60),
# SEEDS ("3 4 5"), BOUT_SECONDS (60), WALL_S (each bout's wall-clock budget, 420), TRACKER, PY,
# GRAPH_WORKERS (16). One process per (config, seed); all run at once.
set -u
PY=${PY:-python3}
OUT=${OUT:-/tmp/devout}; mkdir -p "$OUT"
CONFIGS=${CONFIGS:-"close=infighter+close,outboxer+close plain=infighter,outboxer"}
SEEDS=${SEEDS:-"1 2 3 4 5 6 7 8"}; SECONDS_BOUT=${BOUT_SECONDS:-60}; WALL_S=${WALL_S:-420}
TRACKER=${TRACKER:-search:early:yawtol=0.35:aim=3:touch=10:spread=3:duel}; GRAPH_WORKERS=${GRAPH_WORKERS:-16}
GRAPH=${GRAPH:-}
source benchmarks/device_setup.sh
rm -rf /tmp/igf_device_bouts; mkdir -p /tmp/igf_device_bouts; T0=$(date +%s)
for cfg in $CONFIGS; do
  # A and B split as physics_rl --styles splits (close=R,THETA and :avoid=A,B keep their commas)
  name=${cfg%%=*}; ab=${cfg#*=}
  read -r a b < <($PY -c "import sys; from tracker.physics_rl import split_styles; print(*split_styles(sys.argv[1]))" "$ab")
  for s in $SEEDS; do
    $PY -m tracker.bout_cli fight --graph $GRAPH --a "$a" --b "$b" --seconds $SECONDS_BOUT --seed $s --tracker "$TRACKER" \
      --no-video --json --max-wall-s $WALL_S --out /tmp/igf_device_bouts/${name}_s$s > /tmp/igf_device_bouts/${name}_s$s.out 2>&1 &
  done
done
wait
echo "bouts done in $(( $(date +%s) - T0 )) s"
$PY - /tmp/igf_device_bouts <<'PY' | tee "$OUT/table.txt"
import glob, json, os, sys
print("bout  simulated_s  falls_a  falls_b  hits_a  hits_b  planned  realised  rt_factor  closing_a  closing_b")
for d in sorted(glob.glob(sys.argv[1] + "/*_s*")):
    p = os.path.join(d, "summary.json")
    if not os.path.isfile(p):
        if os.path.isdir(d):
            print(os.path.basename(d), "no summary")
        continue
    s = json.load(open(p))
    cl = [a.get("closing", "-") for a in s.get("agents", [{}, {}])] + ["-", "-"]
    print(os.path.basename(d), f"{s['seconds']:.1f}", s["falls_a"], s["falls_b"], s["hits_a"], s["hits_b"],
          s["planned_hits"], s["planned_realised"], f"{s['realtime_factor']:.3f}", cl[0], cl[1])
PY
tar czf "$OUT/bouts.tgz" -C /tmp igf_device_bouts
ls -la "$OUT"
