#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: the data-only translator for the reference rod (issue 50, case d) taught twice, its
# teacher tracking the chain's D_s path (--source-simulator chain, as the chain's rod_ident_sim)
# or the rod's own (--source-simulator rod), everything else the chain's teacher_rod_ident and
# rod_ident_sim settings: planned in the arm identified from the rod's babbling
# (results/paper/chain_2026-11-28/run/identify_rod/identify.json) at k = 20 (the rod's step
# time by the rule), started from the chain's CCGAN-GP (results/paper/rerun_2026-11-27).
#
#   bash tools/device/rod_source.sh teachers   # both teachers at once -> $OUT/teachers.tar
#   bash tools/device/rod_source.sh distill    # both distillations at once, then
#                                              # studies.rod_transfer -> $OUT/distill.tar
#   bash tools/device/rod_source.sh shapes     # the five shapes in the rod, once -> $OUT/shapes_*
#
# Sequence of `run` calls (nvidia-h200, timeout_s 600), as made on 2026-12-01:
#   1. carry [".whl"]: teachers (about 200 s, both at once). Untar into the repository HERE.
#   2. The tree (~39 MiB) leaves no room for .whl and both teachers (6 MiB each) in one call:
#      PIECES=2 bash tools/device/cut_wheels.sh HERE, then carry [".whl-extra1",
#      "runs/rod_source/chain/teacher"] with a command that only sources install.sh, and at
#      once carry [".whl-extra2", "runs/rod_source/rod/teacher"]: distill (both distillations
#      about 340 s at once; the study's 12 programs about 360 s more, so a second call may be
#      needed: the same study command alone, on the warm machine).
#   3. carrying nothing, on the warm machine: shapes (about 255 s per translator scored).
# Results: studies/results/h200/rod_source/ (its README).
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
phase=${1:?teachers, distill or shapes}
RUN=runs/rod_source
IDENT=results/paper/chain_2026-11-28/run/identify_rod/identify.json
START=results/paper/rerun_2026-11-27/run/ccgan
CHAIN_SIM=results/paper/rerun_2026-11-27/run/ccgan_sim
COMMON=(--model models/softarm.xml --domain constrained --teach-domain "$IDENT" --hold-factor 20
  --duration-s 60 --n-train 120 --n-train-full 120 --n-val 8 --n-val-full 8 --teacher-shard 256
  --window-s 60 --horizon-steps 1 --iterations 1 --teacher-backend mjx --teacher-substeps 2)
TRAIN=(--batch-size 80 --learning-rate 1e-3 --final-lr-factor 0.02 --epochs 1840
  --eval-every 1840 --generator-unroll 10 --score-substeps 5)
VARIANTS=(chain rod)
export XLA_PYTHON_CLIENT_PREALLOCATE=false # two processes share the GPU
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
mkdir -p "$RUN"

run_both() { # run_both LOGNAME CMD-BUILDER: one process per variant, at once; fails if either does
  local pids=() v status=0
  for v in "${VARIANTS[@]}"; do
    "$2" "$v" >"$RUN/$v/$1.log" 2>&1 &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid" || status=1; done
  for v in "${VARIANTS[@]}"; do echo "== $v" && tail -n 4 "$RUN/$v/$1.log"; done
  return $status
}
teacher() {
  local t0=$SECONDS
  $PY -m ccgan.distill "${COMMON[@]}" --batch-size 32 --source-simulator "$1" --teacher-only \
    --out "$RUN/$1/teacher" || return 1
  echo "$1 teacher: wall $((SECONDS - t0)) s"
}
distill() {
  local t0=$SECONDS
  $PY -m ccgan.distill "${COMMON[@]}" "${TRAIN[@]}" --source-simulator "$1" \
    --translators "$START"/translator_seed{0,1,2}.ckpt --seeds 0 1 2 \
    --teacher-from "$RUN/$1/teacher/teacher.npz" --out "$RUN/$1/distill" || return 1
  echo "$1 distill: wall $((SECONDS - t0)) s"
}

case $phase in
teachers)
  for v in "${VARIANTS[@]}"; do mkdir -p "$RUN/$v"; done
  run_both teacher.out teacher
  status=$?
  tar -cf "$OUT/teachers.tar" "$RUN"/*/teacher "$RUN"/*/teacher.out.log
  exit $status
  ;;
distill)
  run_both distill.out distill
  status=$?
  mkdir -p "$RUN/study"
  $PY -m studies.rod_transfer --diagnose --n-shape-like 4 --n-other 2 --out "$RUN/study/rod_transfer" --translators \
    "privileged=$(echo "$CHAIN_SIM"/translator_seed{0,1,2}.ckpt | tr ' ' ,)" \
    "chain_source=$(echo "$RUN"/chain/distill/translator_seed{0,1,2}.ckpt | tr ' ' ,)" \
    "rod_source=$(echo "$RUN"/rod/distill/translator_seed{0,1,2}.ckpt | tr ' ' ,)" \
    || status=1
  tar -cf "$OUT/distill.tar" --exclude='training_state.npz' --exclude='teacher*.npz' \
    "$RUN"/*/distill "$RUN"/*/distill.out.log "$RUN/study"
  exit $status
  ;;
shapes) # the variant that won on held-out programs (chain), scored once
  $PY -m eval.shapes --simulator rod --model models/softarm.xml \
    --methods none stretch ccgan_ident --no-robustness \
    --identified-path "$RUN/chain/distill/translator.ckpt" --out "$OUT/shapes_chain_source"
  ;;
*)
  echo "unknown phase $phase: teachers, distill or shapes" && exit 2
  ;;
esac
