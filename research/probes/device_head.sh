#!/bin/bash
# Rounds of the balance head's search + fit (tracker/layer_head.py) on a machine with many cores
# (on a lent GPU machine's 16 CPU cores; its GPU unused). Run from the repository
# root; the machine needs Python with numpy, scipy, torch and tqdm; mujoco travels as wheels in
# .whl/ (see benchmarks/device_eval.sh), the CMU takes in .devdata/boxing. Env: OUT (results),
# ROUNDS, MINUTES (collection wall minutes per round), WORKERS, RESUME (a head checkpoint to go on
# from; its labels beside it as CKPT.labels.npz are used when present), INSTALL (0: use the
# installed mujoco, not .whl), PY.
# Writes OUT/head.pt (the joint policy's checkpoint with the head), OUT/log.txt and the round's
# labels split into float16 parts of at most 15 MB (OUT/labels_<i>.npz: obs, label, w) so they fit
# what the device tool sends back.
set -u
PY=${PY:-python3}
OUT=${OUT:-/tmp/devout}; mkdir -p "$OUT"
ROUNDS=${ROUNDS:-2}; MINUTES=${MINUTES:-3}; WORKERS=${WORKERS:-16}; RESUME=${RESUME:-}
if [ -d .whl ] && [ "${INSTALL:-1}" = 1 ]; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=$PWD
fi
export IGRAPH_FIGHT_MOCAP=$PWD/.devdata/boxing PYTHONUNBUFFERED=1
nproc; $PY -c "import mujoco, torch, numpy; print('mujoco', mujoco.__version__, 'torch', torch.__version__, 'numpy', numpy.__version__)"
$PY -m tracker.layer_head --out "$OUT/head.pt" ${RESUME:+--resume "$RESUME"} --rounds "$ROUNDS" --minutes "$MINUTES" \
  --workers "$WORKERS" --set eval_walks=0 2>&1 | tee "$OUT/log.txt"
$PY - "$OUT" <<'PY'
import sys, numpy as np
out = sys.argv[1]
z = np.load(out + "/head.pt.labels.npz")
n = len(z["obs"])
per = max(1, int(15e6 // (z["obs"].shape[1] * 2 + 6 * 4 + 4)))
for i, s in enumerate(range(0, n, per)):
    np.savez(f"{out}/labels_{i}.npz", obs=z["obs"][s:s + per].astype(np.float16), label=z["label"][s:s + per],
             w=z["w"][s:s + per])
print(n, "labels in", (n + per - 1) // per, "parts")
PY
rm -f "$OUT/head.pt.labels.npz"
