#!/bin/bash
# The GPU solver (issue "GPU computing") on a machine lent through `device` (an H100/H200 and 16
# cores; its image has numba-cuda and CuPy): one call of about 9 minutes (timeout_s 590).
#
# Prepare on the development machine, in the repository root (out/ is ignored by git):
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --platform manylinux_2_28_x86_64 \
#       -d out/whl meshio pyamg
# then run there, with carry ["out/whl"]:
#   bash benchmarks/device/gpu.sh
# and copy $OUT's gpu_solver.* rows into benchmarks/results/. Each part writes its log at once, so
# a call cut short keeps what it measured.
set -u
pip install -q --no-index --no-deps --target /tmp/site out/whl/*.whl > "$OUT/pip.log" 2>&1
export PYTHONPATH=/tmp/site:$PWD/src NUMBA_CACHE_DIR=/tmp/nc
nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1
# 1. every kernel on the GPU against the CPU's (the tests' scripts without the simulator)
for script in _simulated_operator _simulated_vanka _simulated_multigrid _simulated_step; do
    timeout 150 python "tests/gpu/$script.py" > "$OUT/$script.txt" 2>&1; echo "rc $?" >> "$OUT/$script.txt"
done
cd benchmarks || exit 1
save() { cp results/gpu_solver.* "$OUT/" 2>/dev/null; }
# 2. ten Cate level 1 and 2: the CPU path on 16 cores against the GPU; cycles per solve, device bytes,
#    and at level 1 the CPU in the GPU's colour order: its sphere's velocity after 3 steps is the GPU's
#    to the solves' rounding where the whole step (residuals, solves) is the same
python -m fbmbench gpu_solver --scenes ten-cate --levels 1 --rows gpu colours slabs --steps 3 --tag device-L1 \
    >> "$OUT/log.txt" 2>&1; save
if [ "$SECONDS" -lt 300 ]; then
    python -m fbmbench gpu_solver --scenes ten-cate --levels 2 --rows gpu slabs --steps 2 --tag device-L2 \
        >> "$OUT/log.txt" 2>&1; save
fi
# 3. level 3 (15.8 M unknowns) on the GPU: does it fit, and one step's time, if the call has time left
if [ "$SECONDS" -lt 420 ]; then
    timeout $((560 - SECONDS)) python -m fbmbench gpu_solver --scenes ten-cate --levels 3 --rows gpu --steps 1 \
        --tag device-L3 >> "$OUT/log.txt" 2>&1; save
fi
