#!/bin/bash
# Process scaling (the 16-process targets of "Past one machine") on a machine lent through
# `device` (16 cores): one call of about 8 minutes (timeout_s 590).
#
# Prepare on the development machine, in the repository root (out/ is ignored by git):
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --platform manylinux_2_28_x86_64 \
#       --platform manylinux_2_5_x86_64 -d out/whl meshio pyamg threadpoolctl tqdm mpi4py mpich
# then run there, with carry ["out/whl"]:
#   bash benchmarks/device/processes.sh
# and copy $OUT's distributed_particles.* rows (tags device-*) into benchmarks/results/.
# The rows, most needed first, each a `distributed_particles` run of ten Cate E4 at the scene's
# defaults on multigrid, 2 steps (the second timed; the first builds the hierarchies):
#   level 2 on 16 processes of one thread and on one process of one thread (the strong-scaling
#   target: 10x), level 1 on 2 processes (the weak-scaling target: level 2 on 16 within 1.5x of
#   its time per step), then, while the call has time, level 2 on one process of 16 threads and
#   on 8 and 4 processes, and on 16 processes in slabs (1 x 1 x 16) against the chosen 1 x 2 x 8
#   blocks (tags of their own: a tag's rows replace that tag's earlier ones; their speed-ups
#   against device-L2's 1 x 1 row are worked out by hand).
# A dry run here (level 0 and 1, 2 processes; this machine's Python): QUICK=1 OUT=/tmp/out bash
# benchmarks/device/processes.sh, with the wheels of this machine's Python in out/whl.
set -u
: "${OUT:?the folder the results go to}"
QUICK=${QUICK:-0}
python3 -m venv --system-site-packages /tmp/fbm-venv > "$OUT/setup.log" 2>&1
/tmp/fbm-venv/bin/pip install -q --no-index --no-deps out/whl/*.whl >> "$OUT/setup.log" 2>&1
export PATH=/tmp/fbm-venv/bin:$PATH PYTHONPATH=$PWD/src NUMBA_CACHE_DIR=/tmp/fbm-numba
# MPI first: two processes name the library; without it nothing below can run
if ! timeout 60 mpiexec -n 2 python -c "from mpi4py import MPI; c = MPI.COMM_WORLD; \
print(c.rank, c.size, MPI.Get_library_version().splitlines()[0])" > "$OUT/mpi_check.txt" 2>&1; then
    echo "mpiexec -n 2 failed: see mpi_check.txt" >> "$OUT/log.txt"
    exit 1
fi
nproc >> "$OUT/mpi_check.txt"
cd benchmarks || exit 1
save() { cp results/distributed_particles.* "$OUT/" 2>/dev/null; }
rows() {  # TAG LEVEL STEPS ROWS... (EXTRA: more settings)
    local tag=$1 level=$2 steps=$3
    shift 3
    python -m fbmbench distributed_particles --rows "$@" --scene ten-cate --level "$level" --steps "$steps" \
        --settings solver.linear=multigrid ${EXTRA:-} --tag "$tag" >> "$OUT/log.txt" 2>&1
    save
    echo "$(date +%T) $tag level $level rows $* done at ${SECONDS}s" >> "$OUT/log.txt"
}
# every kernel compiled (about 50 s) before the timed rows: a kernel that first runs in a timed
# step would count its compilation there
rows warm 0 3 2x1 1x1
if [ "$QUICK" = 1 ]; then
    rows dry-L1 1 2 2x1 1x1
    exit 0
fi
rows device-L2 2 2 16x1 1x1
rows device-L1 1 2 2x1
if [ "$SECONDS" -lt 400 ]; then rows device-L2-more 2 2 1x16 8x1; fi
if [ "$SECONDS" -lt 470 ]; then rows device-L2-4 2 2 4x1; fi
if [ "$SECONDS" -lt 500 ]; then EXTRA=solver.process_grid=1x1x16 rows device-L2-slabs 2 2 16x1; fi
