#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`): the chain's two distillations (ccgan_sim at
# k = 15, aged_sim at k = 20; results/paper/rerun_2026-11-26) again from the same start and the
# same teachers' commands, with another batch size or more optimiser steps. What it answers:
# does a larger batch (the step is latency-bound on the GPU, so it costs about the same) or a
# longer training close the gap to the 752-program, 5,520-step run (docs/distillation.md,
# "Batch, steps, and the aged pair's k")? And at which k does the aged pair belong? Everything
# is picked on the 16 held-out 60 s programs; table_aged:RUN scores the shapes of a chosen run.
#
# Call sequence (nvidia-h100-x1, timeout_s 600), back to back while the machine is warm:
#   1. carry [".whl-extra1", ".teacher_cache/c"]: bash tools/device/distill_schedule.sh
#      (stages half the wheels and a teacher cache; the tree leaves ~17 MiB a call)
#   2. carry [".whl-extra2", ".teacher_cache/aged"]: bash tools/device/distill_schedule.sh RUN...
#   3. bash tools/device/distill_schedule.sh RUN...  (each RUN goes on where the last call
#      stopped it: ccgan.distill keeps its training state at --max-wall-s)
# .teacher_cache/{c,aged}/teacher.npz: the chain's teacher_c and teacher_aged caches (240 + 16
# programs of 60 s; runs/paper/teacher_*/teacher.npz after tools/device/take_state.sh).
# RUN names: {c,aged}[_k<k>]_b<batch>_e<epochs> (k: 15 for c, 20 for aged unless given). A run
# at another k than the carried cache's plans its own teacher first (ccgan.distill, resumable
# across calls like the training). BUDGET_S (default 560) is what the call may use.
# RUN may also be table_aged:<an aged RUN>: the five shapes on the aged arm (eval.shapes, the
# chain's table_aged command) with that run's translators, MuJoCo C on the host's cores, into
# $OUT/table_aged_<RUN>.tar.gz (shapes.md, shapes.json, plots).
# Returns $OUT/distill_schedule.tar.gz (each run's folder without its teacher cache) and each
# finished run's own planned teacher as $OUT/teacher_<RUN>.npz.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
WORK=$TMP/distill_schedule
mkdir -p "$WORK"
for arm in c aged; do # the carried caches, kept while the machine is warm
  [[ -f .teacher_cache/$arm/teacher.npz ]] || continue
  mkdir -p "$WORK/cache/$arm" && cp -f .teacher_cache/$arm/teacher.npz "$WORK/cache/$arm/"
done
[[ $# == 0 ]] && { ls -la "$WORK/cache"/* 2>/dev/null; exit 0; }
$PY -c "import mujoco.mjx" || { echo "mujoco not installed yet: carry .whl-extra2"; exit 1; }
start=$SECONDS
left() { echo $((${BUDGET_S:-560} - (SECONDS - start))); }
CHAIN=results/paper/rerun_2026-11-26/run/ccgan # the chain's CCGAN-GP: every run starts from it
for name in "$@"; do
  if [[ $name == table_aged:* ]]; then
    run=${name#table_aged:} table=$TMP/table_aged_${name#table_aged:}
    grep -q '"complete": true' "$WORK/$run/distill.json" 2>/dev/null ||
      { echo "$name: $run has not finished" >&2; break; }
    timeout "$(left)" $PY -m eval.shapes --model models/softarm.xml --target-domain aged \
      --methods none stretch ccgan_sim --ccgan-sim-path "$WORK/$run/translator.ckpt" \
      --robust-methods stretch ccgan_sim --out "$table" || break
    tar -czf "$OUT/table_aged_$run.tar.gz" -C "$TMP" "$(basename "$table")"
    continue
  fi
  if [[ ! $name =~ ^(c|aged)(_k([0-9]+))?_b([0-9]+)_e([0-9]+)$ ]]; then
    echo "bad run name $name: want {c,aged}[_k<k>]_b<batch>_e<epochs>" >&2
    exit 2
  fi
  arm=${BASH_REMATCH[1]} batch=${BASH_REMATCH[4]} epochs=${BASH_REMATCH[5]}
  domain=constrained k=15
  [[ $arm == aged ]] && domain=aged k=20
  cache=(--teacher-from "$WORK/cache/$arm/teacher.npz") # the carried caches are the chain's k
  if [[ -n ${BASH_REMATCH[3]} && ${BASH_REMATCH[3]} != "$k" ]]; then
    k=${BASH_REMATCH[3]} cache=()
  fi
  out=$WORK/$name
  if grep -q '"complete": true' "$out/distill.json" 2>/dev/null; then
    echo "$name: done before"
    continue
  fi
  budget=$(($(left) - 40))
  ((budget > 60)) || { echo "$name: no time left in this call"; break; }
  echo "== $name: $domain, k = $k, batch $batch, $epochs epochs, up to $budget s"
  timeout $((budget + 30)) $PY -m ccgan.distill --model models/softarm.xml --domain $domain \
    --start-domain constrained --translators $CHAIN/translator_seed{0,1,2}.ckpt --seeds 0 1 2 \
    --out "$out" --hold-factor $k "${cache[@]}" \
    --duration-s 60 --n-train 120 --n-train-full 120 --n-val 8 --n-val-full 8 \
    --teacher-shard 256 --window-s 60 --horizon-steps 1 --iterations 1 --teacher-backend mjx \
    --learning-rate 1e-3 --final-lr-factor 0.02 --batch-size "$batch" --epochs "$epochs" \
    --eval-every $((epochs / 2)) --max-wall-s "$budget"
  status=$?
  echo "$name: ccgan.distill exit status $status (143: stopped at --max-wall-s; run again)"
  ((status == 0)) || break
  [[ ${#cache[@]} == 0 ]] && cp -f "$out/teacher.npz" "$OUT/teacher_$name.npz"
done
tar -czf "$OUT/distill_schedule.tar.gz" -C "$TMP" --exclude 'distill_schedule/cache' \
  --exclude 'distill_schedule/*/teacher*.npz' distill_schedule
echo "call: $((SECONDS - start)) s"
ls -la "$OUT"
