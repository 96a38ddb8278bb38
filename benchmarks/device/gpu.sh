#!/bin/bash
# The GPU solver (issue "GPU computing") on a machine lent through `device` (an H100/H200 and 16
# cores; its image has numba-cuda and CuPy, not meshio or pyamg). A session has 15 minutes of
# device time in all, the machine's start (a minute or more) included: the measurements are stages
# in the order the issue needs them, each run only where the time left allows it, and a second
# call on the still-warm machine goes on with the stages the first did not finish.
#
# Prepare on the development machine, in the repository root (out/ is ignored by git):
#   pip download --no-deps --only-binary=:all: --python-version 3.12 --platform manylinux_2_28_x86_64 \
#       -d out/whl meshio pyamg
# then, with carry ["out/whl"]:
#   run  bash benchmarks/device/gpu.sh 560      (timeout_s 590)
#   and at once, where `status` leaves B seconds: bash benchmarks/device/gpu.sh $((B - 45))
#   (timeout_s B - 30); then give_back. Copy $OUT's gpu_solver.json rows (their tags begin with
#   "device-") and profile into benchmarks/results/ after each call; make the table with
#   studies.gpu_solver.table.
#
# The stages (seconds: the least a stage is started with, estimated from this machine's 2-core
# timings, not measured there):
#   checks    (150) every kernel on the GPU against the CPU's, and a whole step: the four test
#                   scripts without the simulator, at once (each compiles its own kernels; a tiny
#                   mesh each), their output in checks.txt
#   L2-gpu    (120) ten Cate level 2, the issue's target, on the GPU: 2 steps, cycles per solve,
#                   device bytes, the kernels' launches; one more step under cProfile
#   L2-cpu    (200) the same on the 16 CPU cores (slab order, the CPU's default): the target's ratio
#                   (a tag of its own: a run replaces the rows of its tag)
#   L3-gpu    (180) level 3 (15.8 M unknowns) on the GPU: does it fit, one step's time
#   L1        (150) level 1: the GPU, the GPU launching once per colour (the launches' cost), the
#                   CPU in the GPU's colour order (its sphere velocity the GPU's to the solves'
#                   rounding) and in slab order
# Each stage is cut at the call's end (timeout kills its processes); a stage cut short is run again
# by the next call, one that ended (whatever its exit code) is not. $OUT holds at most 5 files:
# log.txt (every stage's output; the rows' JSON lines), checks.txt, gpu_solver.json and the
# profile.
set -u
budget=${1:-560}
deadline=$((SECONDS + budget))
done_file=/tmp/fbmflow-gpu-stages  # the stages that ended on this machine (kept while it is warm)
log="$OUT/log.txt"
touch "$done_file"
if [ ! -d /tmp/site ]; then
    pip install -q --no-index --no-deps --target /tmp/site out/whl/*.whl >> "$log" 2>&1 \
        || echo "== the wheels in out/whl did not install: meshio and pyamg missing" >> "$log"
    nvidia-smi >> "$log" 2>&1
fi
export PYTHONPATH=/tmp/site:$PWD/src NUMBA_CACHE_DIR=/tmp/nc PYTHONUNBUFFERED=1
save() {
    cp benchmarks/results/gpu_solver.json "$OUT/" 2>/dev/null
    cp benchmarks/results/gpu_solver.profile-device-* "$OUT/" 2>/dev/null
}
stage() {  # stage NAME SECONDS COMMAND: COMMAND (bash) where SECONDS are left, cut at the deadline
    local name=$1 least=$2 left=$((deadline - SECONDS)) rc start=$SECONDS
    if grep -qx "$name" "$done_file"; then
        echo "== $name: ended in an earlier call" >> "$log"
    elif [ "$left" -lt "$least" ]; then
        echo "== $name: not started, $left s left of this call (it needs about $least)" >> "$log"
    else
        echo "== $name: started at $SECONDS s of this call" >> "$log"
        timeout "$left" bash -c "$3" >> "$log" 2>&1
        rc=$?
        if [ "$rc" = 124 ]; then
            echo "== $name: cut at the call's end after $((SECONDS - start)) s" >> "$log"
        else
            echo "$name" >> "$done_file"
            echo "== $name: exit $rc after $((SECONDS - start)) s" >> "$log"
        fi
        save
    fi
}
bench="cd benchmarks && python -m fbmbench gpu_solver --scenes ten-cate"
stage checks 150 'for s in operator vanka multigrid step; do
        (timeout 200 python tests/gpu/_simulated_$s.py > /tmp/check-$s.txt 2>&1; echo "exit $?" >> /tmp/check-$s.txt) &
    done; wait; for s in operator vanka multigrid step; do echo "== $s"; cat /tmp/check-$s.txt; done > "$OUT/checks.txt"
    grep -h "^exit" /tmp/check-*.txt'
stage L2-gpu 120 "$bench --levels 2 --rows gpu --steps 2 --tag device-L2 --profile gpu"
stage L2-cpu 200 "$bench --levels 2 --rows slabs --steps 2 --tag device-L2-cpu"
stage L3-gpu 180 "$bench --levels 3 --rows gpu --steps 1 --tag device-L3"
stage L1 150 "$bench --levels 1 --rows gpu gpu-colours colours slabs --steps 3 --tag device-L1"
echo "== the call ends at $SECONDS s; stages ended on this machine: $(tr '\n' ' ' < "$done_file")" >> "$log"
