#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`): the CCGAN-GP study of issue 29 on the committed
# arm, resumable across calls. Each call does what is missing, in order, and returns everything as
# $OUT/ccgan_study.tar.gz (unpack it into studies/results/<machine>/ and commit it):
#   1. babbling at the paper's scale in D_s and D_c (MuJoCo C on the host's cores: 53 x 60 s per
#      domain take seconds there, where MJX compiles for a minute);
#   2. F_s and F_c (`ccgan.train --forward-only`);
#   3. trials of `ccgan.tune` until STUDY_SECONDS (default 300) have passed, in batches of
#      TRIALS_PER_BATCH (default 16), each trial scored in the D_c simulator.
# Call sequence (nvidia-h100-x1, timeout_s 600), back to back while the machine is warm:
#   1. carry [".whl"] (tools/device/fetch_wheels.sh): bash tools/device/ccgan_study.sh install
#      (or, when the tree and .whl pass 64 MiB: carry [".whl-extra1"] holding the mujoco and glfw
#      wheels, then [".whl-extra2", ".whl-optuna"] holding mujoco-mjx, pyopengl and trimesh, each
#      folder with a copy of .whl/SHA256SUMS; install.sh installs once all are staged)
#   2. carry [".whl-optuna"] (pip download optuna and matplotlib for Python 3.12 into it; optuna is
#      not on the GPU image), with the previous calls' ccgan_study/ folder in the tree:
#      STUDY_SECONDS=300 bash tools/device/ccgan_study.sh
#   or, after the study: bash tools/device/ccgan_study.sh budget --batch 0 --max-trials 8 --epochs 160
#      --stretch-every 40 (studies.ccgan_budget: the study's budget against a longer training)
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
$PY - <<'PYEOF'
from importlib import metadata
for d in ("optuna", "sqlalchemy", "alembic", "matplotlib", "tqdm", "flax", "optax"):
    try:
        print(f"  {d} {metadata.version(d)}")
    except metadata.PackageNotFoundError:
        print(f"  {d} -")
PYEOF
[[ ${1:-} == install ]] && exit 0
if [[ ${1:-} == budget ]]; then # studies.ccgan_budget on the committed study folder
  $PY -m studies.ccgan_budget --study-dir studies/results/h100/ccgan_study "${@:2}" \
    --out "$OUT/ccgan_budget"
  exit
fi

echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
# The study's folder: the one a previous call returned (committed under studies/results/), else new.
STUDY=${STUDY_DIR:-studies/results/h100/ccgan_study}
RUN=$TMP/ccgan_study
mkdir -p "$RUN"
# (Only into a fresh machine's folder: a warm one's storage holds trials of its earlier calls.)
[[ -d $STUDY && ! -f $RUN/study.db ]] && cp -a "$STUDY"/. "$RUN"/
MODEL=models/softarm.xml
DATA="--source $RUN/babble/source_train.npz $RUN/babble/source_val.npz
      --constrained $RUN/babble/constrained_train.npz $RUN/babble/constrained_val.npz"
start=$SECONDS
if [[ ! -f $RUN/babble/manifest.json ]]; then
  $PY -m mjx_arm.babble --preset paper --domain both --seed 0 --backend c --model $MODEL \
    --out "$RUN/babble" --no-progress || exit 1
  echo "babble: $((SECONDS - start)) s"
fi
if [[ ! -f $RUN/forward/forward_c.ckpt ]]; then
  $PY -m ccgan.train $DATA --model $MODEL --workdir "$RUN/forward" --forward-only --no-progress \
    || exit 1
  echo "forward: $((SECONDS - start)) s"
fi
# No new batch after STUDY_SECONDS; a batch in flight when the call's limit nears is cut by
# `timeout` (its trials stay RUNNING in the storage and are not counted), so the files come back.
hard=$((${CALL_SECONDS:-560} - (SECONDS - start) - 15))
# STUDY_NAME and FORWARD_WORKDIR start another study in the same storage with another F_c
# (e.g. an F_c of studies.forward_data; its report goes to report_<name>/).
NAME=${STUDY_NAME:-ccgan_paper_scale}
REPORT=$RUN/report
[[ $NAME != ccgan_paper_scale ]] && REPORT=$RUN/report_$NAME
# TUNE_ARGS: more ccgan.tune flags, after the defaults (so they win), e.g. "--k-choice-programs
# shape_like --k-choice-n-programs 6 --k-choice-seconds 30 --hold-factors 15 20".
# shellcheck disable=SC2086
timeout "$hard" $PY -m ccgan.tune $DATA --model $MODEL \
  --forward-workdir "${FORWARD_WORKDIR:-$RUN/forward}" --storage "$RUN/study.db" --study-name "$NAME" \
  --n-trials 256 --trials-per-batch "${TRIALS_PER_BATCH:-16}" --timeout-s "${STUDY_SECONDS:-300}" \
  --epochs 40 --stretch-every 20 --hold-factors 10 15 20 --k-choice-seconds 20 \
  --report-dir "$REPORT" --no-progress ${TUNE_ARGS:-}
echo "study call: $((SECONDS - start)) s"
tar -czf "$OUT/ccgan_study.tar.gz" -C "$TMP" ccgan_study
ls -la "$OUT"
