#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: issue 51's translator over the range of media (`python -m ccgan.distill_range`, its
# one-GPU settings), its teacher in four parts at once on the one GPU.
#
#   bash tools/device/media_range.sh teacher   # 4 parts at once (--teacher-ks), ~6 min
#   bash tools/device/media_range.sh distill   # the training run, reading the parts; SIGTERM at
#                                              # 420 s, so rerun it until it ends (exit 0)
#   bash tools/device/media_range.sh references # per-medium translators at (4, 0.8), (20, 0.65)
#   bash tools/device/media_range.sh score     # eval.media_range on held-out programs
#
# A plan for one session's 30 minutes (not yet run as a whole): calls 1-2 the wheels' two pieces
# (tools/device/cut_wheels.sh), the second with the teacher; call 3 G_c's two widths side by
# side, `bash tools/device/media_range.sh distill & RANGE_NAME=range_h96
# DISTILL_ARGS="--generator-hidden 96" bash tools/device/media_range.sh distill; wait`
# (studies/results/cpu/range_fit/: the 32-unit G_c under-fits); call 4 the same again (both
# resume). Score both on held-out media afterwards (the score phase, RANGE_NAME=...).
#
# The default sample's 24 training media take k in {5, 10, 15, 20, 25, 30, 40, 50, 60}
# (measured in MuJoCo C on the 2-core AMD EPYC, 2026-12-02); the MJX tracker is bound by its
# steps' latency, so a part's time grows with the sum of its k plus one compile per k. The
# parts below hold 65, 65, 65 and 60 of the 255. Carry the wheels in the first call (the tree
# is too large beside the whole .whl: .whl-extra1/ with the mujoco, mujoco_mjx and trimesh wheels
# and their lines of SHA256SUMS, 18.9 MB, is enough under MUJOCO_GL=disable) and make
# each later one within the machine's 30 s idle release (the warm machine keeps runs/). Run on
# one H200 on 2026-12-03 (studies/results/h200/media_range/): the teacher 456 s; the training
# about 6.5 epochs/s plus 60-70 s per validation, so 1840 epochs take two distill calls.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
phase=${1:?teacher, distill, references or score}
RUN=runs/media_range
START=results/paper/rerun_2026-11-27/run/ccgan # the chain's CCGAN-GP, three seeds
PARTS=("60 5" "50 15" "40 25" "30 20 10")
export XLA_PYTHON_CLIENT_PREALLOCATE=false # processes share the GPU
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
mkdir -p "$RUN"

case $phase in
teacher)
  pids=() status=0 t0=$SECONDS
  for i in "${!PARTS[@]}"; do
    # shellcheck disable=SC2086 # each part's k, word-split on purpose
    timeout -s TERM "${TEACHER_LIMIT_S:-530}" \
      $PY -m ccgan.distill_range --out "$RUN/part$i" --teacher-ks ${PARTS[$i]} \
      >"$OUT/part$i.log" 2>&1 & # in $OUT: a call stopped at its limit still returns them
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid" || status=1; done
  for i in "${!PARTS[@]}"; do
    echo "== part $i (k ${PARTS[$i]})" && grep -a "teacher (mjx)\|wrote\|media:" "$OUT/part$i.log"
    cp "$OUT/part$i.log" "$RUN/"
  done
  echo "teacher parts: wall $((SECONDS - t0)) s"
  # the shards come back too: a machine lost between calls is refilled by carrying them
  # (in 15 MB pieces: a file over 16 MiB does not come back; `cat ...part-* | tar -x` here)
  tar -cf - "$RUN"/part{0,1,2,3} | split -b 15M -d - "$OUT/teacher_parts.tar.part-"
  ls -la "$OUT"/teacher_parts.tar.part-*
  exit $status
  ;;
distill)
  t0=$SECONDS
  # A machine lost after the teacher call: the parts come back carried as one xz tar
  # (runs/media_range_carry/teacher_parts.tar.xz, 10.4 MB, beside the tree without the wheels).
  carried=runs/media_range_carry/teacher_parts.tar.xz
  if [[ ! -f $RUN/part0/teacher.npz && -f $carried ]]; then
    xz -dc "$carried" | tar -x && echo "teacher parts from $carried"
  fi
  # SIGTERM at 420 s: the process then validates once more (60-70 s for 24 media on the
  # H200's host) and saves; KILL 120 s later. The training state is also saved at every
  # validation, so a kill loses at most eval_every epochs.
  # shellcheck disable=SC2086 # DISTILL_ARGS, word-split on purpose
  # RANGE_NAME (default range) names the run's folder, so that two trainings (e.g. G_c's width:
  # RANGE_NAME=range_h96 DISTILL_ARGS="--generator-hidden 96") run side by side on one GPU.
  name=${RANGE_NAME:-range}
  timeout -k 120 -s TERM "${DISTILL_LIMIT_S:-420}" $PY -m ccgan.distill_range --out "$RUN/$name" \
    --teacher-from "$RUN"/part{0,1,2,3} ${DISTILL_ARGS:-} >"$RUN/$name.log" 2>&1
  status=$?
  tail -n 4 "$RUN/$name.log"
  echo "distill $name: rc $status, wall $((SECONDS - t0)) s (143: stopped, rerun to go on)"
  # the training state (1.4 MB) comes back, the teacher (10 MB) stays: a lost machine resumes
  tar -cf "$OUT/distill_$name.tar" --exclude=teacher.npz "$RUN/$name" "$RUN/$name.log"
  exit $status
  ;;
references)
  # Per-medium translators at two held-out media of the range, for issue 51's 1.25x criterion:
  # each the chain's CCGAN-GP distilled (teacher planned, then 1,840 epochs) in that medium
  # alone, with the range's teacher settings (PAPER_SETTINGS: 2 physics steps per planning
  # period, programs of 60 s) and the per-pair stage's program count, at the rule's k. Both at
  # once beside whatever else runs; SIGTERM at REF_LIMIT_S, rerun to go on (teacher by shard).
  # REF_MEDIA picks some of them ("r s k" triples, ";" between), e.g. REF_MEDIA="4 0.8 10".
  pids=() status=0 t0=$SECONDS
  IFS=';' read -r -a ref_media <<<"${REF_MEDIA:-4 0.8 10;20 0.65 50}"
  for medium in "${ref_media[@]}"; do
    read -r r s k <<<"$medium"
    dir=$RUN/ref_r${r}_s${s}
    mkdir -p "$dir"
    $PY -c "import json, sys, mjx_arm; from mjx_arm import media
from mjx_arm.identify_family import resolved_viscosity_scale as scale
r, s, c = float(sys.argv[1]), float(sys.argv[2]), scale(mjx_arm.load(domain='constrained'))
json.dump({'domain': {'viscosity_scale': media.viscosity_scale_of(r, c), 'stiffness_scale': s}},
          open(sys.argv[3], 'w'))" "$r" "$s" "$dir/medium.json" || exit 1
    timeout -k 120 -s TERM "${REF_LIMIT_S:-420}" $PY -m ccgan.distill \
      --translators "$START"/translator_seed{0,1,2}.ckpt --seeds 0 1 2 --model models/softarm.xml \
      --domain identified --start-domain constrained --teach-domain "$dir/medium.json" \
      --out "$dir" --hold-factor "$k" --duration-s 60 --n-train 120 --n-train-full 120 \
      --n-val 8 --n-val-full 8 --teacher-shard 256 --window-s 60 --batch-size 80 \
      --horizon-steps 1 --iterations 1 --teacher-backend mjx --teacher-substeps 2 \
      --learning-rate 1e-3 --final-lr-factor 0.02 --epochs 1840 --eval-every 460 \
      --generator-unroll 10 --score-substeps 5 >"$dir.log" 2>&1 &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid" || status=1; done
  for dir in "$RUN"/ref_r*/; do
    echo "== ${dir%/}" && tr '\r' '\n' <"${dir%/}.log" | grep -a "teacher\|wrote\|held-out\|resum" | tail -5
  done
  echo "references: wall $((SECONDS - t0)) s (rc 1 where one stopped: rerun to go on)"
  tar -cf "$OUT/references.tar" --exclude='teacher*.npz' "$RUN"/ref_r*
  exit $status
  ;;
score)
  mkdir -p "$RUN/score"
  name=${RANGE_NAME:-range}
  $PY -m eval.media_range --translators "$RUN/$name"/translator_seed{0,1,2}.ckpt \
    --out "$RUN/score/$name" \
    --reference 10 1 results/paper/rerun_2026-11-27/run/ccgan_sim/translator.ckpt \
    --reference 10 0.7 results/paper/rerun_2026-11-27/run/aged_sim/translator.ckpt \
    --reference 4 0.8 "$RUN"/ref_r4_s0.8/translator.ckpt \
    --reference 20 0.65 "$RUN"/ref_r20_s0.65/translator.ckpt \
    >"$RUN/score.log" 2>&1
  status=$?
  tail -n 20 "$RUN/score.log"
  tar -cf "$OUT/score.tar" "$RUN/score" "$RUN/score.log"
  exit $status
  ;;
*)
  echo "unknown phase $phase: teacher, distill, references or score" && exit 2
  ;;
esac
