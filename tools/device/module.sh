#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent
# there: one benchmark or study module, its outputs into $OUT (they come back to the caller).
#
#   bash tools/device/module.sh MODULE [ARGS...]   # python -m MODULE ARGS --out $OUT/<name>
#
# (<name>: MODULE's last part, e.g. bench.sharing -> $OUT/sharing.{md,json}; a study likewise:
#  studies.program_length -> $OUT/program_length.)
# Sequence of `run` calls (nvidia-h200 or nvidia-h100-x1, timeout_s 600):
#   1. carry [".whl"] (from tools/device/fetch_wheels.sh): bash tools/device/module.sh
#      (installs mujoco only)
#   2. at once, carrying nothing: bash tools/device/module.sh MODULE ARGS...
# Copy what comes back into bench/results/<machine>/ or studies/results/<machine>/.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
[[ $# == 0 ]] && exit 0
module=$1
shift
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
$PY -m "$module" "$@" --out "$OUT/${module##*.}"
