#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`): the distillation over whole programs
# (issue 30). Work accumulates in $TMP/issue30 while the machine is warm; every call returns all
# of it but the teacher caches (teacher*.npz) as $OUT/issue30.tar.gz (unpack into studies/results/<machine>/).
#
# Call sequence (one H100 or H200, timeout_s 600), back to back while the machine is warm:
#   1. carry [".whl"] (bench/device/fetch_wheels.sh; before it dropped MuJoCo Studio from
#      mujoco's wheel, the wheels came in two halves, .whl-extra1 and .whl-extra2, over two
#      calls): bash studies/issue30_gpu.sh install
#   2. bash studies/issue30_gpu.sh bench [bench.teacher flags]
#      the teacher in MuJoCo C on the host's cores beside MJX on the GPU (bench/results/<gpu>).
#   3. bash studies/issue30_gpu.sh teacher K [ccgan.distill flags]
#      the teacher's commands for the programs (ccgan.distill --teacher-only), cached in
#      $TMP/issue30/distill_kK/teacher.npz; a call stopped at its deadline (exit status 143)
#      keeps its finished shards and the simulator states of the one in progress
#      (teacher_partial.npz): the same call again goes on from there.
#   4. bash studies/issue30_gpu.sh distill K [ccgan.distill flags]
#      G_c of the chain's CCGAN-GP on this arm (studies/results/h200/issue29/chain/ccgan) taught over the cached
#      whole programs, held out on 60 s programs; the same flags as step 3 (the cache's key).
#   4b. bash studies/issue30_gpu.sh rerun K [the same flags]
#      a second distillation on a copy of the same teacher cache (distill_kK_run2): run to run.
#   SUFFIX=_fresh before steps 3 and 4 plans and distills in distill_kK_fresh instead: a second
#   run from an empty folder, the teacher replanned.
#   DOMAIN=aged before steps 3 and 4 distills for the aged arm (stiffness x0.7) in aged_kK: G_c
#   starts from the same D_c CCGAN-GP (--start-domain constrained), the teacher tracks in the
#   aged arm.
#   TEACHER_FROM=FILE before steps 3-4 starts the folder with that teacher cache (a teacher.npz
#   brought back from an earlier machine, in pieces: the device returns files of a few MB, and
#   carried in an ignored folder such as .teacher_cache/): a fresh machine need not replan it.
#   BUDGET_S=S (default 570) is what one invocation may use of a call: two in one call share it.
#   3b/4b'. bash studies/issue30_gpu.sh pair teacher|distill K1 K2 [the same flags]
#      step 3 or 4 for two hold factors at once on the one GPU (no preallocation), each
#      logging to its folder's stage.log.
#   5. bash studies/issue30_gpu.sh length K [studies.program_length flags]
#      the distilled translators, their teacher and stretch only on held-out 60 s programs.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../bench/device/install.sh" || exit 1
[[ ${1:-} == install ]] && exit 0
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
MODEL=models/softarm.xml
RUN=$TMP/issue30
mkdir -p "$RUN"
start=$SECONDS
pack() {
  tar -czf "$OUT/issue30.tar.gz" -C "$TMP" --exclude 'issue30/*/teacher*.npz' issue30
  echo "call: $((SECONDS - start)) s"
  ls -la "$OUT"
}
left() { echo $((${BUDGET_S:-570} - (SECONDS - start))); } # BUDGET_S: seconds this script may use of the call
START=studies/results/h200/issue29/chain/ccgan
DOMAIN=${DOMAIN:-constrained}
PREFIX=distill_k
[[ $DOMAIN == constrained ]] || PREFIX=${DOMAIN}_k
distill() { # distill() OUT_DIR K [--teacher-only] [ccgan.distill flags]
  local out=$1 k=$2
  shift 2
  if [[ -n ${TEACHER_FROM:-} ]]; then # a teacher cache carried from an earlier machine
    mkdir -p "$out" && cp --update=none "$TEACHER_FROM" "$out/teacher.npz" || return 1
  fi
  timeout "$(left)" $PY -m ccgan.distill --model $MODEL --domain "$DOMAIN" \
    --start-domain constrained \
    --translators $START/translator_seed{0,1,2}.ckpt --seeds 0 1 2 --hold-factor "$k" \
    --teacher-backend mjx --horizon-steps 1 --iterations 1 --out "$out" \
    --max-wall-s $(($(left) - 60)) "$@"
  echo "ccgan.distill exit status $? (143: stopped at --max-wall-s; the same call again goes on)"
}
case ${1:-} in
bench)
  shift
  timeout "$(left)" $PY -m bench.teacher --model $MODEL --out "$RUN/teacher_bench" "$@"
  pack
  ;;
teacher)
  k=$2
  shift 2
  distill "$RUN/$PREFIX$k${SUFFIX:-}" "$k" --teacher-only "$@"
  pack
  ;;
distill)
  k=$2
  shift 2
  distill "$RUN/$PREFIX$k${SUFFIX:-}" "$k" "$@"
  pack
  ;;
rerun)
  k=$2
  shift 2
  mkdir -p "$RUN/distill_k${k}_run2"
  cp --update=none "$RUN/distill_k$k/teacher.npz" "$RUN/distill_k${k}_run2/" || exit 1
  distill "$RUN/distill_k${k}_run2" "$k" "$@"
  pack
  ;;
pair)
  # two stages at once on the one GPU, each logging to its folder's stage.log; what a teacher
  # costs beside another is in the logs' per-25-step times (bench/device/teacher_sharing.sh)
  stage=$2 k1=$3 k2=$4
  shift 4
  [[ $stage == teacher ]] && set -- --teacher-only "$@"
  export XLA_PYTHON_CLIENT_PREALLOCATE=false # two processes share the GPU's memory
  for k in "$k1" "$k2"; do
    mkdir -p "$RUN/$PREFIX$k${SUFFIX:-}"
    distill "$RUN/$PREFIX$k${SUFFIX:-}" "$k" "$@" >>"$RUN/$PREFIX$k${SUFFIX:-}/stage.log" 2>&1 &
  done
  wait
  tail -n 3 "$RUN/$PREFIX$k1${SUFFIX:-}/stage.log" "$RUN/$PREFIX$k2${SUFFIX:-}/stage.log"
  pack
  ;;
length)
  k=$2
  shift 2
  timeout "$(left)" $PY -m studies.program_length --model $MODEL \
    --translators "$RUN"/distill_k"$k"/translator_seed{0,1,2}.ckpt --out "$RUN/length_k$k" "$@"
  pack
  ;;
*)
  echo "usage: bash studies/issue30_gpu.sh install|bench|teacher|distill|pair|rerun|length ..." >&2
  exit 2
  ;;
esac
