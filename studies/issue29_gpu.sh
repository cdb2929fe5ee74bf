#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`): F_c's data study (studies.forward_data) and
# the CCGAN-GP ablation (studies.ccgan_ablation) on the committed study folder
# (studies/results/h100/ccgan_study). Work accumulates in $TMP/issue29 while the machine is warm;
# every call returns all of it as $OUT/issue29.tar.gz (unpack into studies/results/<machine>/).
#
# Call sequence (one H100 or H200, timeout_s 600), back to back while the machine is warm:
#   1. carry [".whl-extra1"]: bash studies/issue29_gpu.sh install (and so on for each piece of
#      bench/device/cut_wheels.sh but the last)
#   2. carry [the last ".whl-extraN"]: bash studies/issue29_gpu.sh forward
#      babbling on the host's cores (MuJoCo C): "scale" (400 x 60 s per domain, the paper's
#      0.5-3 s holds) and "long" (400 x 120 s in D_c, 1-40 s holds); then the F_c runs.
#   3. carry [".finetune_in"]: bash studies/issue29_gpu.sh finetune [ccgan.finetune flags]
#   3. bash studies/issue29_gpu.sh ablation "LABEL" [studies.ccgan_ablation flags] [-- "LABEL2" ...]
#      `--forward-c best` takes the F_c of the forward study with the lowest X_err at k = 15;
#      `--gan-data scale-data` the "scale" babbling; `--gan-data shape-data` 200 + 1 shape-like
#      programs of 60 s per domain (babbled here on first use); `--setting-from /tmp/ccgan_study/study.db:NAME`
#      the best trial of a study that studies/ccgan_study.sh ran on this machine (optuna installed).
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../bench/device/install.sh" || exit 1
[[ ${1:-} == install ]] && exit 0
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
STUDY=studies/results/h100/ccgan_study
MODEL=models/softarm.xml
RUN=$TMP/issue29
# A fresh machine starts from the committed results (the forward study's F_c, the ablation so far).
COMMITTED=studies/results/h200/issue29
[[ -d $RUN || ! -d $COMMITTED ]] || cp -a "$COMMITTED" "$RUN"
mkdir -p "$RUN"
start=$SECONDS
pack() {
  tar -czf "$OUT/issue29.tar.gz" -C "$TMP" --exclude 'issue29/babble_*' issue29
  echo "call: $((SECONDS - start)) s"
  ls -la "$OUT"
}

case ${1:-} in
forward)
  babble() { # name, then mjx_arm.babble flags
    local name=$1
    shift
    [[ -f $RUN/babble_$name/manifest.json ]] && return
    $PY -m mjx_arm.babble --backend c --model $MODEL --out "$RUN/babble_$name" --no-progress "$@" \
      || exit 1
    echo "babble $name: $((SECONDS - start)) s"
  }
  # N_SCALE, N_LONG and STEPS smaller only to rehearse the call on a CPU (DEVICE_TMP=...).
  ns=${N_SCALE:-400} nl=${N_LONG:-400}
  few=$((nl < 50 ? nl : 50)) mid=$((nl / 2))
  babble scale --domain both --n "$ns" --n-val 1 --seed 11
  babble long --domain constrained --n "$nl" --n-val 1 --seed 12 --duration 120 --hold-min 1 \
    --hold-max 40
  timeout $((560 - (SECONDS - start))) $PY -m studies.forward_data --study-dir $STUDY \
    --data scale="$RUN/babble_scale" long="$RUN/babble_long" \
    --runs paper:50:teacher:10 "scale:$ns:teacher:10" "long:$few:teacher:10" \
    "long:$mid:teacher:10" "long:$nl:teacher:10" paper:50:open:150 "long:$few:open:150" \
    "long:$mid:open:150" "long:$nl:open:150" \
    --steps "${STEPS:-4000}" --batch-size 64 --hold-factors 1 10 15 20 --out "$RUN/forward_data"
  pack
  ;;
ablation)
  shift
  best=$($PY - "$RUN/forward_data/forward_data.json" <<'PYEOF'
import json, sys
runs = json.load(open(sys.argv[1]))["runs"]
print(min(runs, key=lambda r: next(s["kept_cm"] for s in r["scores"] if s["k"] == 15))["name"])
PYEOF
  ) && echo "best F_c at k = 15: $best"
  args=()
  for a in "$@" --; do
    if [[ $a == -- ]]; then
      ((${#args[@]})) || continue
      label=${args[0]}
      flags=("${args[@]:1}")
      for i in "${!flags[@]}"; do
        [[ ${flags[$i]} == best ]] && flags[$i]=$RUN/forward_data/$best/forward_c.ckpt
      done
      for i in "${!flags[@]}"; do
        [[ ${flags[$i]} == scale-data ]] && flags[$i]=$RUN/babble_scale
        if [[ ${flags[$i]} == shape-data ]]; then
          flags[$i]=$RUN/babble_shape
          [[ -f $RUN/babble_shape/manifest.json ]] || $PY -m mjx_arm.babble --backend c \
            --model $MODEL --out "$RUN/babble_shape" --no-progress --programs shape_like \
            --domain both --n 200 --n-val 1 --seed 13 --duration 60 || exit 1
        fi
      done
      timeout $((570 - (SECONDS - start))) $PY -m studies.ccgan_ablation --study-dir $STUDY \
        --label "$label" "${flags[@]}" --out "$RUN/ablation"
      echo "$label: $((SECONDS - start)) s"
      args=()
    else
      args+=("$a")
    fi
  done
  pack
  ;;
finetune)
  # ccgan.finetune (feedback through the MJX simulator) from the chain's CCGAN-GP, carried in
  # .finetune_in/ (translator_seed{0,1,2}.ckpt of the chain's ccgan stage); ccgan.finetune flags
  # follow. FINETUNE_NAME names its folder in $RUN (default: finetune).
  shift
  timeout $((570 - (SECONDS - start))) $PY -m ccgan.finetune --model $MODEL \
    --translators .finetune_in/translator_seed{0,1,2}.ckpt --seeds 0 1 2 \
    --out "$RUN/${FINETUNE_NAME:-finetune}" "$@"
  pack
  ;;
*)
  echo "usage: bash studies/issue29_gpu.sh install|forward|ablation|finetune ..." >&2
  exit 2
  ;;
esac
