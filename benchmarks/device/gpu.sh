#!/bin/bash
# The GPU solver (issue "GPU computing") on a machine lent through `device` (an H100/H200 and 16
# cores; its image has numba-cuda and CuPy): two calls of up to about 9 minutes each (timeout_s
# 590), the machine kept warm between them; the main target (level 2) comes first.
#
# Prepare on the development machine, in the repository root (out/ is ignored by git):
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --platform manylinux_2_28_x86_64 \
#       -d out/whl meshio pyamg
# then run there, with carry ["out/whl"]:
#   bash benchmarks/device/gpu.sh 1    # the kernels and a whole step against the CPU's; level 2
#   bash benchmarks/device/gpu.sh 2    # level 1 (with the CPU in colour order); level 3
# and copy $OUT's gpu_solver.* rows into benchmarks/results/ after each. Each part writes its log at
# once, so a call cut short keeps what it measured.
set -u
part=${1:-1}
pip install -q --no-index --no-deps --target /tmp/site out/whl/*.whl > "$OUT/pip.log" 2>&1
export PYTHONPATH=/tmp/site:$PWD/src NUMBA_CACHE_DIR=/tmp/nc
save() { cp benchmarks/results/gpu_solver.* "$OUT/" 2>/dev/null; }
bench() { (cd benchmarks && python -m fbmbench gpu_solver "$@" >> "$OUT/log.txt" 2>&1); save; }
if [ "$part" = 1 ]; then
    nvidia-smi > "$OUT/nvidia-smi.txt" 2>&1
    # 1. every kernel on the GPU against the CPU's, and a whole step (the tests' scripts without the
    #    simulator; the first compiles the kernels)
    for script in _simulated_operator _simulated_vanka _simulated_multigrid _simulated_step; do
        timeout 120 python "tests/gpu/$script.py" > "$OUT/$script.txt" 2>&1; echo "rc $?" >> "$OUT/$script.txt"
    done
    # 2. ten Cate level 2, the target: the GPU against the CPU path on 16 cores; cycles per
    #    solve, device bytes, the kernels' launches (host seconds in them); one more GPU step
    #    under cProfile (gpu_solver.profile-*.txt: where the host's time goes)
    bench --scenes ten-cate --levels 2 --rows gpu slabs --steps 2 --tag device-L2 --profile gpu
else
    # 3. level 1, and the CPU in the GPU's colour order: its sphere's velocity after 3 steps is the
    #    GPU's to the solves' rounding where the whole step is the same; gpu-colours: the smoothers
    #    launching once per colour instead of once per sweep (the launches' cost)
    bench --scenes ten-cate --levels 1 --rows gpu gpu-colours colours slabs --steps 3 --tag device-L1
    # 4. level 3 (15.8 M unknowns) on the GPU: does it fit, and one step's time, if time is left
    if [ "$SECONDS" -lt 360 ]; then
        timeout $((560 - SECONDS)) bash -c "cd benchmarks && python -m fbmbench gpu_solver --scenes ten-cate \
            --levels 3 --rows gpu --steps 1 --tag device-L3" >> "$OUT/log.txt" 2>&1; save
    fi
fi
