#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there. Two pieces of issue 50 in the same calls:
#
# (d) the rod: one step of iterative learning control for the data-only translator. The
#     committed data-only rod translator (studies/results/h200/rod_source/chain_source, k = 20)
#     is run on the 256 teacher programs in the rod (float32, GPU) and in the arm identified from
#     the rod's babbling; the teacher then tracks x_s - (rod - arm) there
#     (`ccgan.distill --correction-translator`), and the student is distilled from the chain's
#     CCGAN-GP with the chain's settings, then scored in the rod on held-out programs
#     (studies.rod_transfer) beside the uncorrected translator.
# (b) the aged arm, identified from 50 of its programs of 60 s (studies.identify_targets, with
#     half and twice D_c's drag for (c)), then a translator taught on the identified arm (k chosen
#     there among 20, 25, 30), scored on the five shapes beside the privileged aged_sim.
#
#   bash tools/device/rod_correction.sh teachers  # corrected teacher + identification -> $OUT
#   bash tools/device/rod_correction.sh distill   # corrected distill + aged teacher -> $OUT
#   bash tools/device/rod_correction.sh score     # aged distill + rod_transfer -> $OUT
#   bash tools/device/rod_correction.sh shapes    # the five shapes once (rod; aged) -> $OUT
#
# Sequence of `run` calls (nvidia-h200, timeout_s 600), as made on 2026-12-02: carry [".whl"]
# in the first; each later call within the machine's 30 s idle release, carrying nothing (the
# warm machine keeps the installed wheels and runs/). Results: studies/results/h200/rod_correction/.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
phase=${1:?teachers, distill, score or shapes}
RUN=runs/rod_correction
IDENT_ROD=results/paper/chain_2026-11-28/run/identify_rod/identify.json
UNCORRECTED=studies/results/h200/rod_source/chain_source
START=results/paper/rerun_2026-11-27/run/ccgan
AGED_SIM=results/paper/rerun_2026-11-27/run/aged_sim
IDENT_AGED=$RUN/identify_50/aged/identify.json
PROGRAMS=(--duration-s 60 --n-train 120 --n-train-full 120 --n-val 8 --n-val-full 8
  --teacher-shard 256 --window-s 60 --horizon-steps 1 --iterations 1 --teacher-backend mjx)
ROD=(--model models/softarm.xml --domain constrained --teach-domain "$IDENT_ROD" --hold-factor 20
  "${PROGRAMS[@]}" --teacher-substeps 2 --correction-translator "$UNCORRECTED/translator_seed0.ckpt")
AGED=(--model models/softarm.xml --domain aged --teach-domain "$IDENT_AGED" --k-candidates 20 25 30
  "${PROGRAMS[@]}" --teacher-substeps 5)
TRAIN=(--batch-size 80 --learning-rate 1e-3 --final-lr-factor 0.02 --epochs 1840
  --eval-every 1840 --generator-unroll 10 --score-substeps 5)
SEEDS=(--translators "$START"/translator_seed{0,1,2}.ckpt --seeds 0 1 2)
export XLA_PYTHON_CLIENT_PREALLOCATE=false # processes share the GPU
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
mkdir -p "$RUN/rod" "$RUN/aged" "$RUN/identify_50"

timed() { # timed NAME LOG CMD...: runs CMD into LOG, prints its wall time and the log's tail
  local name=$1 log=$2 t0=$SECONDS status
  shift 2
  "$@" >"$log" 2>&1
  status=$?
  echo "== $name: rc $status, wall $((SECONDS - t0)) s" && tail -n 4 "$log"
  return $status
}
identify_media() { # aged, half and twice D_c's drag from 50 programs of 60 s, at once
  local pids=() status=0 c
  for c in aged half_drag double_drag; do
    timed "identify $c" "$RUN/identify_50/$c.log" $PY -m studies.identify_targets \
      --out "$RUN/identify_50" --case "$c" --n 50 --duration 60 &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid" || status=1; done
  $PY -m studies.identify_targets --out "$RUN/identify_50" --case || status=1 # the table, once
  return $status
}

case $phase in
teachers)
  timed "rod corrected teacher" "$RUN/rod/teacher.out.log" $PY -m ccgan.distill "${ROD[@]}" \
    --batch-size 32 --teacher-only --out "$RUN/rod/distill" &
  teacher=$!
  identify_media
  status=$?
  wait $teacher || status=1
  tar -cf "$OUT/teachers.tar" --exclude='teacher*.npz' --exclude='*.npz' "$RUN"
  exit $status
  ;;
distill)
  timed "rod corrected distill" "$RUN/rod/distill.out.log" $PY -m ccgan.distill "${ROD[@]}" \
    "${TRAIN[@]}" "${SEEDS[@]}" --out "$RUN/rod/distill" &
  student=$!
  timed "aged identified teacher" "$RUN/aged/teacher.out.log" $PY -m ccgan.distill "${AGED[@]}" \
    --batch-size 32 --teacher-only --out "$RUN/aged/distill"
  status=$?
  wait $student || status=1
  tar -cf "$OUT/distill.tar" --exclude='training_state.npz' --exclude='teacher*.npz' \
    "$RUN"/rod "$RUN"/aged
  exit $status
  ;;
score)
  timed "aged identified distill" "$RUN/aged/distill.out.log" $PY -m ccgan.distill "${AGED[@]}" \
    "${TRAIN[@]}" "${SEEDS[@]}" --start-domain constrained --out "$RUN/aged/distill" &
  student=$!
  mkdir -p "$RUN/study"
  timed "rod_transfer" "$RUN/study/rod_transfer.log" $PY -m studies.rod_transfer \
    --n-shape-like 4 --n-other 2 --out "$RUN/study/rod_transfer" --translators \
    "uncorrected=$(echo "$UNCORRECTED"/translator_seed{0,1,2}.ckpt | tr ' ' ,)" \
    "corrected=$(echo "$RUN"/rod/distill/translator_seed{0,1,2}.ckpt | tr ' ' ,)"
  status=$?
  wait $student || status=1
  tar -cf "$OUT/score.tar" --exclude='training_state.npz' --exclude='teacher*.npz' \
    "$RUN"/aged "$RUN/study"
  exit $status
  ;;
shapes) # scored once, after the schedule is fixed: the rod (if the corrected one won) and aged
  timed "rod shapes" "$OUT/rod_shapes.log" $PY -m eval.shapes --simulator rod \
    --model models/softarm.xml --methods none stretch ccgan_ident --no-robustness \
    --identified-path "$RUN/rod/distill/translator.ckpt" --out "$OUT/shapes_rod_corrected" &
  rod=$!
  timed "aged shapes" "$OUT/aged_shapes.log" $PY -m eval.shapes --model models/softarm.xml \
    --target-domain aged --methods none stretch ccgan_sim ccgan_ident --no-robustness \
    --ccgan-sim-path "$AGED_SIM/translator.ckpt" \
    --identified-path "$RUN/aged/distill/translator.ckpt" --out "$OUT/shapes_aged_identified"
  status=$?
  wait $rod || status=1
  exit $status
  ;;
*)
  echo "unknown phase $phase: teachers, distill, score or shapes" && exit 2
  ;;
esac
