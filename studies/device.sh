#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: one study, its outputs into $OUT (they come back to the caller).
#
#   bash studies/device.sh NAME [ARGS...]    # python -m studies.NAME ARGS --out $OUT/NAME
#
# Sequence of `run` calls (nvidia-h200 or nvidia-h100-x1, timeout_s 600):
#   1. carry [".whl"] (from bench/device/fetch_wheels.sh): bash studies/device.sh
#      (installs mujoco only)
#   2. at once, carrying nothing: bash studies/device.sh NAME ARGS...
# The studies run MuJoCo C on the host's cores (16 on the lent machines); copy what comes back
# into studies/results/<machine>/.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../bench/device/install.sh" || exit 1
[[ $# == 0 ]] && exit 0
name=$1
shift
nproc
$PY -m "studies.$name" "$@" --out "$OUT/$name"
