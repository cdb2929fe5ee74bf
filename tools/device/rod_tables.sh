#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: the tables scored in the reference rod, with the commands of the rod_table and
# rod_table_aged stages of experiments/paper.json but the distilled translators of the committed
# chain run (CHAIN_RUN, default results/paper/rerun_2026-11-27/run) instead of this run's own, so
# the rod's stages can be measured without running the whole chain again. rod_table needs the
# rod's trainings done by tools/device/chain.sh in this warm machine ($TMP/paper, STAGES="rod_data
# rod_data_long rod_tracker rod_forward rod_ccgan rod_wcgan"; rod_tracker's cache is read when
# there); rod_table_aged needs nothing but the tree, so
# it can run beside them. The tables named in WHICH run at once, in one call, their rod rollouts
# split over the host's cores (one JAX CPU device per core, as experiments.paper's stages get on
# a GPU machine), each into $TMP/rod_tables/<table>/, returned as
# $OUT/rod_tables_<table>.tar.gz (the device returns at most 8 files).
#
#   WHICH=rod_table_aged bash tools/device/rod_tables.sh &   # beside chain.sh in one call
#   bash tools/device/rod_tables.sh                          # default WHICH="rod_table rod_table_aged"
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
RUN_DIR=$TMP/paper
CHAIN_RUN=${CHAIN_RUN:-results/paper/rerun_2026-11-27/run}
WHICH=${WHICH:-rod_table rod_table_aged}
TABLES=$TMP/rod_tables
mkdir -p "$TABLES"
export XLA_PYTHON_CLIENT_PREALLOCATE=false
# The rod on the host's cores, as experiments.paper gives its stages (mjx_arm.rod_arm.host_devices).
export XLA_FLAGS="${XLA_FLAGS:-} --xla_force_host_platform_device_count=$(nproc)"
common=(--simulator rod --model models/softarm.xml --no-robustness)
pids=()
for table in $WHICH; do
  case $table in
  rod_table)
    needs=("$RUN_DIR/rod_ccgan/translator.ckpt" "$RUN_DIR/rod_wcgan/translator.ckpt"
      "$CHAIN_RUN/ccgan_sim/translator.ckpt")
    args=(--methods none stretch ccgan wcgan ccgan_sim mpc
      --ccgan-path "$RUN_DIR/rod_ccgan/translator.ckpt"
      --wcgan-path "$RUN_DIR/rod_wcgan/translator.ckpt"
      --distilled-path "$CHAIN_RUN/ccgan_sim/translator.ckpt")
    # The tracker planned by the rod_tracker stage, as the stage's --caches-from reads it.
    [[ -d $RUN_DIR/rod_tracker ]] && args+=(--caches-from "$RUN_DIR/rod_tracker") ;;
  rod_table_aged)
    needs=("$CHAIN_RUN/aged_sim/translator.ckpt")
    args=(--target-domain aged --methods none stretch ccgan_sim
      --distilled-path "$CHAIN_RUN/aged_sim/translator.ckpt") ;;
  *) echo "unknown table $table (rod_table or rod_table_aged)" && exit 2 ;;
  esac
  for need in "${needs[@]}"; do
    [[ -f $need ]] || { echo "$table: missing $need (run the rod's stages first)" && exit 1; }
  done
  echo "[$table] $PY -m eval.shapes ${common[*]} ${args[*]} --out $TABLES/$table"
  (
    start=$(date +%s)
    $PY -m eval.shapes "${common[@]}" "${args[@]}" --out "$TABLES/$table" >"$TABLES/$table.log" 2>&1
    rc=$?
    echo "[$table] exit $rc after $(($(date +%s) - start)) s" | tee -a "$TABLES/$table.log"
    tail -3 "$TABLES/$table.log"
    tar -czf "$OUT/rod_tables_$table.tar.gz" -C "$TABLES" "$table" "$table.log"
    exit $rc
  ) &
  pids+=($!)
done
rc=0
for pid in "${pids[@]}"; do wait "$pid" || rc=1; done
exit $rc
