#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: the latency levers of the 30-minute chain (docs/chain.md), measured in one call before
# the chain uses them, each row set beside its baseline on the same machine:
#   bench.distill_step   the distillation's Adam step at G_c unrolls 1, 10 and 25;
#   bench.teacher        the MJX teacher planned in the arm (25 steps per period) and in
#                        planning copies of 5 and 2 steps, each scored in the arm;
#   bench.oracle         the oracle's Adam steps through a copy of 5 steps (if time is left).
# Each runs under its own time limit, so one slow row set cannot take the call's 600 s.
#
# Sequence of `run` calls (nvidia-h100-x1, timeout_s 600) on a fresh machine:
#   1. carry [".whl-extra1"]: bash tools/device/planning.sh   (stages half the wheels)
#   2. at once, carry [".whl-extra2"]: bash tools/device/planning.sh
# Copy what comes back into bench/results/<gpu>/planning/.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
$PY -c "import mujoco.mjx" 2>/dev/null || exit 0 # staging call: the other half comes next
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
start=$SECONDS
timeout 150 $PY -m bench.distill_step --unrolls 1 10 25 --out "$OUT/distill_step"
echo "distill_step: $((SECONDS - start)) s"
# (With --c-programs 4 --mjx-programs 256 --substeps 0 5 2 under a 270 s limit, on 2026-11-27,
# this row set wrote nothing: each planner compiles for about a minute. Hence fewer rows.)
timeout 300 $PY -m bench.teacher --k 15 --duration 5 --c-programs 1 --mjx-programs 64 \
  --substeps 0 2 --out "$OUT/teacher_planning"
echo "teacher: $((SECONDS - start)) s"
left=$((520 - SECONDS))
if ((left > 120)); then
  timeout "$left" $PY -m bench.oracle --horizons 2 --programs 5 --k 15 --substeps 5 --steps 3 \
    --out "$OUT" --tag _planning
fi
echo "all: $((SECONDS - start)) s"
