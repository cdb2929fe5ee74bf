#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: the chain of experiments/paper.json, resumed from where the last call stopped.
#
#   bash tools/device/chain.sh            # install what was carried, run until the deadline
#   RUN=0 bash tools/device/chain.sh      # install only
#
# Each call: installs the carried wheels (tools/device/install.sh); restores the run folder from
# a carried .paper_state/paper_state.tar.gz when the machine does not hold it already; runs
# `python -m experiments.paper --out $TMP/paper --jobs ${JOBS:-6} --deadline-s ${DEADLINE_S:-500}`
# (up to JOBS stages at once, of which one training per GPU: the config's "gpu" stages take
# turns; a stage stopped at the deadline keeps its folder and continues
# in the next call); puts into $OUT paper_results.tar.gz (what docs/chain.md says to commit),
# paper.md, the log and the GPU's use sampled every 15 s, and the whole run folder as
# paper_state.tar.gz.part-NN (pieces of 15 MiB: the device returns no larger file) with
# paper_state.sha256 when they fit the 8 files a call returns. The deadline, the 60 s a stopped stage may take to end its
# epoch and checkpoint (experiments.stages.STOP_GRACE_S), the install and the packing stay under
# the device's 600 s per call. Keep DEADLINE_S at about 500: at 550 the 600 s limit came during the
# packing and the call returned nothing (results/paper/rerun_2026-11-26/README.md, call 2).
#
# Sequence of `run` calls (nvidia-h100-x1 or nvidia-h200, or a kind of several GPUs, where each
# stage gets a GPU of its own; timeout_s 600):
#   1. carry [".whl"]:   bash tools/device/chain.sh
#      The tree is now too large to travel beside the whole .whl (64 MiB a call):
#      `bash tools/device/cut_wheels.sh` here cuts it into .whl-extra1..N/ (N = 3 beside a 54 MiB
#      tree, 4 at 55 MiB: it prints N); carry them one per call, each with `RUN=0 bash tools/device/chain.sh` but the last,
#      which runs the chain (results/paper/rerun_2026-11-27/README.md: the same with two halves).
#   2.. carry nothing, each within the machine's 30 s warm window: bash tools/device/chain.sh
#      (the run folder is still in /tmp/paper), until the command says every stage is done.
#      A machine is held at most 30 minutes: three calls of ~520 s fit, a fourth does not; start
#      the next machine as below.
#   If the machine was lost: carry [".whl"] with `RUN=0 bash tools/device/chain.sh`, then at once
#   carry [".paper_state"] (the last returned state; the .whl and the state do not fit one call
#   beside the tree) with `bash tools/device/chain.sh`. When the state and the tree exceed the
#   64 MiB a call carries: `bash tools/device/take_state.sh --pieces 3` here cuts the kept state
#   into .paper_state_part1..3/, and the calls carry [".whl-extra1", ".paper_state_part1"],
#   [".whl-extra2", ".paper_state_part2"] (both with RUN=0), then [".paper_state_part3"] with
#   `bash tools/device/chain.sh` (the .whl halves: tools/device/install.sh). A second run beside a kept one uses its
#   own folder: STATE_DIR=.paper_state_NAME here and there (carry [".paper_state_NAME"]).
# Here, after each call: bash tools/device/take_state.sh FILES_AT (joins and checks the pieces into
# the git-ignored .paper_state/). Finished: bash tools/device/take_state.sh FILES_AT runs/ unpacks
# the run folder too; commit what docs/chain.md names.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
source "$(dirname "${BASH_SOURCE[0]}")/pieces.sh" || exit 1 # join_pieces
RUN_DIR=$TMP/paper
STATE_DIR=${STATE_DIR:-.paper_state} # another run's state folder keeps runs apart (take_state.sh)
# A state too large to travel beside the tree and the wheels comes in pieces over several calls
# (`take_state.sh --pieces N` cuts it into .paper_state_part1/ ... each with the whole file's
# sha256): each call stages what it carried in $TMP/state_parts, and once every piece is there they
# are joined, checked and restored from.
for dir in "$STATE_DIR"_part[0-9]*; do
  [[ -d $dir ]] || continue
  mkdir -p "$TMP/state_parts" && cp -f "$dir"/* "$TMP/state_parts/"
  echo "staged state piece(s) $(cd "$dir" && ls -- *.part-* | tr '\n' ' ')from $dir"
done
if [[ ! -d $RUN_DIR && -f $TMP/state_parts/paper_state.sha256 ]]; then
  join_pieces "$TMP/state_parts" paper_state.tar.gz paper_state.sha256 state
  case $? in
  0) STATE_DIR=$TMP/state_parts ;;
  2) echo "not restored" && exit 1 ;;
  esac
fi
if [[ ! -d $RUN_DIR && -f $STATE_DIR/paper_state.tar.gz ]]; then
  tar -xzf "$STATE_DIR/paper_state.tar.gz" -C "$TMP" && echo "restored $RUN_DIR from $STATE_DIR"
fi
[[ ${RUN:-1} == 0 ]] && exit 0
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
CONFIG=${CONFIG:-experiments/paper.json} # experiments/quick.json rehearses the calls anywhere
# GPU use every 15 s, to see how well the stages share the GPU (appended over calls).
nvidia-smi --query-gpu=timestamp,utilization.gpu,memory.used --format=csv,noheader -l 15 \
  >>"$TMP/gpu_use.csv" 2>/dev/null &
sampler=$!
# Several GPUs: each stage gets one (--devices), and as many stages run as there are GPUs, at
# least 6 (at the start: both babblings, both teachers and the oracle, then forward).
n_gpus=$(nvidia-smi -L 2>/dev/null | grep -c '^GPU' || true)
devices=()
if ((n_gpus > 1)); then
  devices=(--devices $(seq 0 $((n_gpus - 1))))
  JOBS=${JOBS:-$((n_gpus > 6 ? n_gpus : 6))}
fi
# STAGES="a b ..." runs only those stages (their inputs must be done or among them).
only=()
[[ -n ${STAGES:-} ]] && only=(--stage $STAGES)
$PY -m experiments.paper --out "$RUN_DIR" --config "$CONFIG" --jobs "${JOBS:-6}" "${devices[@]}" \
  "${only[@]}" --deadline-s "${DEADLINE_S:-500}" 2>&1 |
  tee -a "$TMP/paper_log.txt"
rc=${PIPESTATUS[0]}
kill $sampler 2>/dev/null
$PY -m experiments.paper --out "$RUN_DIR" --config "$CONFIG" --list
# The device returns files of at most 16 MiB (8 files, 64 MiB in all): the state travels in
# pieces of 15 MiB with the whole file's sha256; tools/device/take_state.sh joins them here.
# What docs/chain.md says to commit comes back every call in one small file, whatever the
# state's size: paper_results.tar.gz, the run folder without the babbling data, the training
# states and the caches (translators, forward models, metrics, stage.json/log, tables).
tar -czf "$OUT/paper_results.tar.gz" -C "$TMP" --exclude=babble --exclude=state.ckpt \
  --exclude='*.npz' --exclude='*.replaced-*' paper
cp -f "$TMP/paper_log.txt" "$OUT/log.txt"
[[ -f $TMP/gpu_use.csv ]] && cp -f "$TMP/gpu_use.csv" "$OUT/"
[[ -f $RUN_DIR/paper.md ]] && cp -f "$RUN_DIR/paper.md" "$OUT/"
# The whole state, for a fresh machine, in the slots left (8 files a call): with the rod's and
# the identified arm's stages it can outgrow them; then it stays on this machine only (the next
# call must come within the warm window) and the call says so.
tar -czf "$TMP/paper_state.tar.gz" -C "$TMP" paper
slots=$((8 - $(ls "$OUT" | wc -l) - 1))
pieces=$((($(stat -c %s "$TMP/paper_state.tar.gz") + 15 * 1048576 - 1) / (15 * 1048576)))
if ((pieces <= slots)); then
  (cd "$TMP" && sha256sum paper_state.tar.gz) >"$OUT/paper_state.sha256"
  split -b 15M -d "$TMP/paper_state.tar.gz" "$OUT/paper_state.tar.gz.part-"
else
  echo "WARNING: the state is $pieces pieces of 15 MiB, $slots fit: not returned; it is on this" \
    "machine only (call again within the warm window), the results are in paper_results.tar.gz"
fi
rm -f "$TMP/paper_state.tar.gz"
echo "experiments.paper exit status $rc (3: stopped at the deadline, call again); in \$OUT: $(ls "$OUT" | tr '\n' ' ')"
exit $rc
