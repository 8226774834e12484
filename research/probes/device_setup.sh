# Sourced by the device_*.sh benchmarks (run from the repository root on a lent machine): puts the
# repository on PYTHONPATH, installs the wheels in .whl/ when INSTALL is set (mujoco and what it
# needs: see benchmarks/device_eval.sh), prints the versions, builds the graph from .devdata/boxing
# into /tmp/g.igz unless GRAPH is set (GRAPH_WORKERS threads; log in $OUT/build.log), prints its
# content hash, and sets one thread per process for the bout processes that follow.
# Needs PY, OUT, GRAPH (may be empty) and GRAPH_WORKERS; sets GRAPH.
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
# one thread per bout process (16 processes ran about 2.5x slower per process than one process on the
# development VM; with one thread each still about 2x,
# later, so the pools were not the cause: research/notes/BOUTS.md)
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 NUMBA_NUM_THREADS=1
