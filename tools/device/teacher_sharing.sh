#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), mujoco installed (tools/device/install.sh):
# does one GPU plan two MJX teachers at once as fast as one? The teacher (tracking.mpc_mjx) is
# latency-bound, so two processes might overlap where trainings do not (bench/results/h200/sharing.md).
#   bash tools/device/teacher_sharing.sh [bench.teacher flags]
# runs `python -m bench.teacher FLAGS` alone, then two copies at once, and puts each run's
# .md/.json into $OUT/teacher_sharing/ with the wall times (wall.txt).
# Every run: no persistent compilation cache (each compiles, as alone; SOFTARM_JAX_CACHE=0) and
# no preallocation (two processes share the GPU's memory: with XLA's default 75% each, the second
# could not create its cuSolver handle).
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
export SOFTARM_JAX_CACHE=0 XLA_PYTHON_CLIENT_PREALLOCATE=false
dir=$OUT/teacher_sharing
mkdir -p "$dir"
flags=("$@")
t0=$SECONDS
$PY -m bench.teacher --out "$dir/alone" "${flags[@]}" >"$dir/alone.log" 2>&1
echo "alone: $((SECONDS - t0)) s" | tee "$dir/wall.txt"
t0=$SECONDS
$PY -m bench.teacher --out "$dir/pair_a" "${flags[@]}" >"$dir/pair_a.log" 2>&1 &
$PY -m bench.teacher --out "$dir/pair_b" "${flags[@]}" >"$dir/pair_b.log" 2>&1 &
wait
echo "two at once: $((SECONDS - t0)) s" | tee -a "$dir/wall.txt"
grep -h "^| MJX" "$dir"/*.md | tee -a "$dir/wall.txt"
tar -czf "$OUT/teacher_sharing.tar.gz" -C "$OUT" teacher_sharing && rm -rf "$dir"
