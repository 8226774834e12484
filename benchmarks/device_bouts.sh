#!/bin/bash
# Many physics bouts side by side on a machine with many cores, each cut at a wall-clock budget
# (tracker.bout_cli fight --max-wall-s): for trackers far slower than real time (the search tracker
# runs at 0.05-0.1x), a lent machine's cores simulate the first seconds of many bouts at once.
# Run from the repository root. The machine needs Python with numpy, numba, scipy, torch, tqdm and
# matplotlib; mujoco can travel as wheels in .whl/ (INSTALL=1 installs them; see
# benchmarks/device_eval.sh for the pip download line), the mocap in .devdata/boxing (the graph is
# built there unless GRAPH is given; its content hash is printed).
# Env: OUT (results: bouts.tgz with every bout's summary.json and log.jsonl, and table.txt),
# CONFIGS ("NAME=A_SPEC,B_SPEC ..."; e.g. "close=infighter+close,outboxer+close plain=infighter,outboxer"),
# SEEDS ("3 4 5"), BOUT_SECONDS (60), WALL_S (each bout's wall-clock budget, 420), TRACKER, PY,
# GRAPH_WORKERS (16). One process per (config, seed); all run at once.
set -u
PY=${PY:-python3}
OUT=${OUT:-/tmp/devout}; mkdir -p "$OUT"
CONFIGS=${CONFIGS:-"close=infighter+close,outboxer+close plain=infighter,outboxer"}
SEEDS=${SEEDS:-"1 2 3 4 5 6 7 8"}; SECONDS_BOUT=${BOUT_SECONDS:-60}; WALL_S=${WALL_S:-420}
TRACKER=${TRACKER:-search:early:yawtol=0.35:aim=3:touch=10:spread=3:duel}; GRAPH_WORKERS=${GRAPH_WORKERS:-16}
GRAPH=${GRAPH:-}
export PYTHONPATH=$PWD
if [ -n "${INSTALL:-}" ]; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl 2>&1 | tail -2
  export PYTHONPATH=/tmp/site:$PWD
fi
nproc; $PY -c "import mujoco, numba, torch, numpy; print('mujoco', mujoco.__version__, 'numba', numba.__version__, 'torch', torch.__version__, 'numpy', numpy.__version__)"
if [ -z "$GRAPH" ]; then
  GRAPH=/tmp/g.igz; t0=$(date +%s)
  $PY -m igraph_fight.cli build --mocap .devdata/boxing --out $GRAPH --workers $GRAPH_WORKERS > "$OUT/build.log" 2>&1 || { tail -40 "$OUT/build.log"; exit 1; }
  echo "graph built in $(( $(date +%s) - t0 )) s"; tail -3 "$OUT/build.log"
fi
$PY -c "import sys; from igraph_fight.graph import load_graph; print('graph content hash', load_graph(sys.argv[1]).content_hash[:12])" "$GRAPH" 2>&1 | tail -1
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
mkdir -p /tmp/bouts; T0=$(date +%s)
for cfg in $CONFIGS; do
  name=${cfg%%=*}; ab=${cfg#*=}; a=${ab%%,*}; b=${ab#*,}
  for s in $SEEDS; do
    $PY -m tracker.bout_cli fight --graph $GRAPH --a "$a" --b "$b" --seconds $SECONDS_BOUT --seed $s --tracker "$TRACKER" \
      --no-video --json --max-wall-s $WALL_S --out /tmp/bouts/${name}_s$s > /tmp/bouts/${name}_s$s.out 2>&1 &
  done
done
wait
echo "bouts done in $(( $(date +%s) - T0 )) s"
$PY - /tmp/bouts <<'PY' | tee "$OUT/table.txt"
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
tar czf "$OUT/bouts.tgz" -C /tmp bouts
ls -la "$OUT"
