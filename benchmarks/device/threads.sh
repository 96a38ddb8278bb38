#!/bin/bash
# Thread scaling on a machine lent through `device` (16 cores): one call of 6-9 minutes (timeout_s 590).
#
# Prepare on the development machine, in the repository root (out/ is ignored by git):
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --platform manylinux_2_28_x86_64 \
#       -d out/whl meshio pyamg threadpoolctl tqdm
#   mkdir -p out/baseline && git archive BASELINE src | tar -x -C out/baseline
# then run there, with carry ["out/whl", "out/baseline"]:
#   bash benchmarks/device/threads.sh THIS_COMMIT BASELINE
# and copy $OUT's thread_scaling.* and smoother_threads.* rows into benchmarks/results/.
set -u
NAME=${1:?this tree's commit}
BASE=${2:?the baseline's commit}
pip install -q --no-index --no-deps --target /tmp/site out/whl/*.whl > "$OUT/pip.log" 2>&1
export PYTHONPATH=/tmp/site NUMBA_CACHE_DIR=/tmp/nc
cd benchmarks || exit 1
save() { cp results/thread_scaling.* results/smoother_threads.* "$OUT/" 2>/dev/null; }
python -m fbmbench smoother_threads --threads 1 2 4 8 16 --tag device-L1 >> "$OUT/log.txt" 2>&1; save
python -m fbmbench thread_scaling --threads 16 8 4 2 --level 1 --name "$NAME" --baseline ../out/baseline/src \
    --baseline-name "$BASE" --baseline-threads 16 2 --tag device-L1 >> "$OUT/log.txt" 2>&1; save
# level 2 at 16 threads (PERFORMANCE.md: 42.4 s per step before this work), if the call has time
if [ "$SECONDS" -lt 330 ]; then
    python -m fbmbench thread_scaling --threads 16 --level 2 --warm 1 --steps 1 --name "$NAME" \
        --tag device-L2 >> "$OUT/log.txt" 2>&1; save
fi
