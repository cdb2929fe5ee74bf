#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there. Two pieces of issue 50, one phase per call (each under the 600 s limit):
#
# (b) the aged arm, identified from 50 of its programs of 60 s (studies.identify_targets, with
#     half and twice D_c's drag for (c)); a translator taught on the identified arm (k chosen
#     there among 20, 25, 30), scored on the five shapes beside the privileged aged_sim.
# (d) the rod: one step of iterative learning control for the data-only translator. The
#     committed data-only rod translator (studies/results/h200/rod_source/chain_source, k = 20)
#     is run on the 256 teacher programs in the rod (float32, GPU) and in the arm identified from
#     the rod's babbling; the teacher then tracks x_s - (rod - arm) there, x_s the rod's own D_s
#     path (`ccgan.distill --correction-translator --source-simulator rod`); the student is
#     distilled from the chain's CCGAN-GP with the chain's settings and scored in the rod on
#     held-out programs (studies.rod_transfer) beside the uncorrected translator.
#
#   bash tools/device/rod_correction.sh identify       # 3 media at once, ~420 s
#   bash tools/device/rod_correction.sh aged_teacher   # ~245 s
#   bash tools/device/rod_correction.sh aged_distill   # ~215 s
#   bash tools/device/rod_correction.sh aged_shapes    # ~90 s
#   bash tools/device/rod_correction.sh aged_ccgan     # CCGAN-GP on the aged arm's data (not run)
#   bash tools/device/rod_correction.sh rod_teacher    # the rod's rollouts (kept, ~550 s) then
#                                                      # the teacher: two calls
#   bash tools/device/rod_correction.sh rod_distill    # ~340 s
#   bash tools/device/rod_correction.sh rod_score      # rod_transfer, ~230 s
#   bash tools/device/rod_correction.sh rod_shapes     # the five shapes in the rod, once, ~250 s
#   bash tools/device/rod_correction.sh offpair        # (c): half and twice D_c's drag, at once
#     (OFFPAIR_TEACH=truth: their privileged references; both ran 2026-12-04, one H200, 387-432 s:
#     studies/results/h200/offpair/)
#   STEP=2 bash tools/device/rod_correction.sh rod_teacher, rod_distill, rod_score: a second
#     step, corrected from the committed corrected translator into runs/rod_correction/rod2
#     (rod_score then scores the three side by side; not yet run)
#
# Carry [".whl"] in the first call; make each later one within the machine's 30 s idle release,
# carrying nothing (the warm machine keeps the installed wheels and runs/). Each phase tars what
# it made into $OUT. As made on 2026-12-02 (one H200): identify ran beside the rod's teacher,
# whose rollouts took 546 s, so that call hit the limit before the teacher planned (nothing of
# it was kept then: the correction cache came after); the four aged phases followed. Results:
# studies/results/h200/aged_identified/ (its README). rod_teacher then ran alone in 484 s with
# the arm's rollouts beside the rod's (studies/results/h200/rod_correction/). All four rod
# phases ran on one warm H200 on 2026-12-02 (376, 294, 226 and 246 s; that folder's README):
# every held-out family within 0.34-0.52x stretch only in the rod, the circle 0.96x. The tree
# and the wheels leave no room to carry the teacher cache (9.7 MB) to a fresh machine, so run
# rod_teacher and rod_distill on one warm machine.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
phase=${1:?a phase: see the header}
RUN=runs/rod_correction
IDENT_ROD=results/paper/chain_2026-11-28/run/identify_rod/identify.json
UNCORRECTED=studies/results/h200/rod_source/chain_source
START=results/paper/rerun_2026-11-27/run/ccgan
AGED_SIM=results/paper/rerun_2026-11-27/run/aged_sim
IDENT_AGED=$RUN/identify_50/aged/identify.json
PROGRAMS=(--duration-s 60 --n-train 120 --n-train-full 120 --n-val 8 --n-val-full 8
  --teacher-shard 256 --window-s 60 --horizon-steps 1 --iterations 1 --teacher-backend mjx)
# The teacher tracks the rod's own D_s path, corrected: the better of the two corrected teachers
# in the rod on held-out programs (studies/results/cpu/correction_teacher/correction_teacher_8.md).
# STEP=2: a second step of the learning control, the correction taken from the first step's
# corrected translator (committed: studies/results/h200/rod_correction/distill/) into rod2/.
STEP=${STEP:-1}
CORRECTED=studies/results/h200/rod_correction/distill
case $STEP in
1) CORRECT_FROM=$UNCORRECTED ROD_DIR=$RUN/rod ;;
2) CORRECT_FROM=$CORRECTED ROD_DIR=$RUN/rod2 ;;
*) echo "STEP=$STEP: 1 or 2" && exit 2 ;;
esac
ROD=(--model models/softarm.xml --domain constrained --teach-domain "$IDENT_ROD" --hold-factor 20
  "${PROGRAMS[@]}" --teacher-substeps 2 --correction-translator "$CORRECT_FROM/translator_seed0.ckpt"
  --source-simulator rod)
AGED=(--model models/softarm.xml --domain aged --teach-domain "$IDENT_AGED" --k-candidates 20 25 30
  "${PROGRAMS[@]}" --teacher-substeps 5)
TRAIN=(--batch-size 80 --learning-rate 1e-3 --final-lr-factor 0.02 --epochs 1840
  --eval-every 1840 --generator-unroll 10 --score-substeps 5)
SEEDS=(--translators "$START"/translator_seed{0,1,2}.ckpt --seeds 0 1 2)
export XLA_PYTHON_CLIENT_PREALLOCATE=false # processes share the GPU
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
mkdir -p "$ROD_DIR" "$RUN/aged" "$RUN/identify_50"

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

pack() { # pack NAME PATHS...: a tar of what a phase made, without the big caches
  local name=$1
  shift
  tar -cf "$OUT/$name.tar" --exclude='training_state.npz' --exclude='*.npz' "$@"
}

case $phase in
identify)
  identify_media
  status=$?
  pack identify "$RUN/identify_50"
  exit $status
  ;;
aged_teacher)
  timed "aged identified teacher" "$RUN/aged/teacher.out.log" $PY -m ccgan.distill "${AGED[@]}" \
    --batch-size 32 --teacher-only --out "$RUN/aged/distill"
  status=$?
  pack aged_teacher "$RUN/aged"
  exit $status
  ;;
aged_distill)
  timed "aged identified distill" "$RUN/aged/distill.out.log" $PY -m ccgan.distill "${AGED[@]}" \
    "${TRAIN[@]}" "${SEEDS[@]}" --start-domain constrained --out "$RUN/aged/distill"
  status=$?
  pack aged_distill "$RUN/aged"
  exit $status
  ;;
offpair) # (c): a translator for each medium off the pair, taught on the arm identified from
  # 50 of its programs (committed: studies/results/h200/aged_identified/identify_50/), k chosen
  # there, the two at once; SIGTERM at OFFPAIR_LIMIT_S, rerun to go on (teacher by shard, the
  # training by its state). Scored afterwards in the true medium on any CPU: eval.shapes
  # --target-domain-file TRUTH.json --taught-medium-rtol 0.05 --methods none stretch ccgan_ident
  # --identified-path .../distill/translator.ckpt (docs/identification.md, "Media off the pair").
  # OFFPAIR_TEACH=truth: the privileged references instead, taught in the true media (the
  # case.json's truth_domain as a plain {"domain": ...} file) into offpair_truth/.
  pids=() status=0 ident=studies/results/h200/aged_identified/identify_50
  for c in half_drag double_drag; do
    if [[ ${OFFPAIR_TEACH:-identified} == truth ]]; then
      dir=$RUN/offpair_truth teach=$dir/$c/truth.json
      mkdir -p "$dir/$c"
      $PY -c "import json,sys; c=json.load(open(sys.argv[1])); d=c['truth_domain']; d.pop('name');
json.dump({'domain': d}, open(sys.argv[2], 'w'))" "$ident/$c/case.json" "$teach"
    else
      dir=$RUN/offpair teach=$ident/$c/identify.json
    fi
    mkdir -p "$dir/$c"
    timeout -k 120 -s TERM "${OFFPAIR_LIMIT_S:-450}" $PY -m ccgan.distill \
      --model models/softarm.xml --domain identified --start-domain constrained \
      --teach-domain "$teach" \
      --k-candidates 5 10 15 20 25 30 40 "${PROGRAMS[@]}" --teacher-substeps 2 "${TRAIN[@]}" \
      "${SEEDS[@]}" --out "$dir/$c/distill" >"$dir/$c.log" 2>&1 &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid" || status=1; done
  for c in half_drag double_drag; do
    echo "== $c" && tr '\r' '\n' <"$dir/$c.log" | grep -a "k =\|wrote\|resum\|stopp" | tail -4
  done
  pack "$(basename "$dir")" "$dir"
  exit $status
  ;;
aged_ccgan) # (b)'s CCGAN-GP on the aged arm's own data: the 50 + 3 programs of 60 s that the
  # identification read (seed 0, the paper's stream "babble/aged/..."), D_s's beside them, and
  # the long babbling for F_c, trained with the chain's ccgan settings, k chosen in the aged arm
  # among 20, 25, 30 (stretch only's best there is 25). AGED_CCGAN_QUICK=1: tiny sizes, to try
  # the path on a CPU (2 min on the 2-core EPYC with DEVICE_TMP, PY and OUT set as in chain.sh's
  # rehearsal; eval.shapes --quick then read its translator). Scored afterwards on any CPU:
  # eval.shapes --target-domain aged
  # --methods ccgan --ccgan-path $RUN/aged_ccgan/train/translator.ckpt.
  dir=$RUN/aged_ccgan
  mkdir -p "$dir"
  if [[ ${AGED_CCGAN_QUICK:-0} == 1 ]]; then
    data=(--n 2 --n-val 1 --duration 4) long=(--n 2 --n-val 1 --duration 8)
    train=(--epochs 2 --stretch-every 1 --hold-factors 2 3 --k-choice-n-programs 1 --n-val 1
      --batch-size 4 --k-choice-seconds 4 --forward-epochs 1 --forward-window 10)
  else
    data=(--preset paper) long=(--n 400 --n-val 1 --duration 120)
    train=(--epochs 60 --stretch-every 20 --hold-factors 20 25 30 --k-choice-n-programs 6
      --k-choice-seconds 30 --forward-epochs 80 --forward-window 150)
  fi
  timed "aged babbling" "$dir/data.log" $PY -m mjx_arm.babble "${data[@]}" --domain source,aged \
    --seed 0 --backend c --model models/softarm.xml --out "$dir/data/babble" || exit 1
  timed "aged long babbling" "$dir/long.log" $PY -m mjx_arm.babble "${long[@]}" --domain aged \
    --seed 12 --hold-min 1 --hold-max 40 --backend c --model models/softarm.xml \
    --out "$dir/long/babble" || exit 1
  b=$dir/data/babble
  timed "aged CCGAN-GP" "$dir/train.log" $PY -m ccgan.train \
    --source "$b/source_train.npz" "$b/source_val.npz" --constrained "$b/aged_train.npz" \
    "$b/aged_val.npz" --model models/softarm.xml --workdir "$dir/train" --seeds 0 1 2 \
    --lambda-cycle 8.663 --lambda-identity 0.5628 --lambda-feedback 47.35 \
    --lr-generator 8.459e-4 --lr-critic 5.846e-5 --patience 1 --k-choice-programs shape_like \
    --k-choice-substeps 5 --forward-data "$dir/long/babble/aged_train.npz" --forward-open-loop \
    --forward-batch-size 64 "${train[@]}"
  status=$?
  tar -cf "$OUT/aged_ccgan.tar" --exclude='*.npz' --exclude='state.ckpt' "$dir"
  exit $status
  ;;
aged_shapes) # scored once, after the schedule is fixed
  timed "aged shapes" "$RUN/aged/shapes.out.log" $PY -m eval.shapes --model models/softarm.xml \
    --target-domain aged --methods none stretch ccgan_sim ccgan_ident --no-robustness \
    --ccgan-sim-path "$AGED_SIM/translator.ckpt" \
    --identified-path "$RUN/aged/distill/translator.ckpt" --out "$RUN/aged/shapes"
  status=$?
  pack aged_shapes "$RUN/aged/shapes" "$RUN/aged/shapes.out.log"
  exit $status
  ;;
rod_teacher) # stopped at the limit, it keeps the rod's rollouts (teacher_correction.npz): rerun
  timed "rod corrected teacher" "$ROD_DIR/teacher.out.log" timeout 560 $PY -m ccgan.distill \
    "${ROD[@]}" --batch-size 32 --teacher-only --out "$ROD_DIR/distill"
  status=$?
  # The rod's rollouts come back too (~7 MB): carried into runs/rod_correction/rod/distill/ of
  # a fresh machine, they spare the next call its ~290 s of rollouts.
  cp -f "$ROD_DIR/distill/teacher_correction.npz" "$OUT/" 2>/dev/null
  pack rod_teacher "$ROD_DIR"
  exit $status
  ;;
rod_distill)
  timed "rod corrected distill" "$ROD_DIR/distill.out.log" $PY -m ccgan.distill "${ROD[@]}" \
    "${TRAIN[@]}" "${SEEDS[@]}" --out "$ROD_DIR/distill"
  status=$?
  pack rod_distill "$ROD_DIR"
  exit $status
  ;;
rod_score) # held-out programs only; the five shapes wait for a win here
  SECOND=$([[ $STEP == 2 ]] && echo 1)
  mkdir -p "$RUN/study"
  timed "rod_transfer" "$RUN/study/rod_transfer.log" $PY -m studies.rod_transfer \
    --n-shape-like 4 --n-other 2 --out "$RUN/study/rod_transfer" --translators \
    "uncorrected=$(echo "$UNCORRECTED"/translator_seed{0,1,2}.ckpt | tr ' ' ,)" \
    "corrected=$(echo "$CORRECTED"/translator_seed{0,1,2}.ckpt | tr ' ' ,)" \
    ${SECOND:+"corrected_twice=$(echo "$RUN"/rod2/distill/translator_seed{0,1,2}.ckpt | tr ' ' ,)"}
  status=$?
  pack rod_score "$RUN/study"
  exit $status
  ;;
rod_shapes) # scored once, after rod_score's held-out win (studies/results/h200/rod_correction/)
  timed "rod shapes" "$RUN/rod/shapes.out.log" $PY -m eval.shapes --simulator rod \
    --model models/softarm.xml --methods none stretch ccgan_ident --no-robustness \
    --identified-path "$RUN/rod/distill/translator.ckpt" --out "$RUN/rod/shapes"
  status=$?
  pack rod_shapes "$RUN/rod/shapes" "$RUN/rod/shapes.out.log"
  exit $status
  ;;
*)
  echo "unknown phase $phase: identify, aged_teacher, aged_distill, aged_shapes, rod_teacher," \
    "rod_distill, rod_score, rod_shapes, offpair or aged_ccgan"
  exit 2
  ;;
esac
