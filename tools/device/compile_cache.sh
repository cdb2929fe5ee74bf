#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`, carrying .whl on a fresh machine): the same
# MJX rollout benchmark in two processes sharing one persistent compilation cache
# (SOFTARM_JAX_CACHE, empty at the start), then once with the cache off. Each run's "compile s"
# column is what the cache saves a second process. Outputs: $OUT/cache_{first,second,off}/.
set -uo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
cache=$TMP/softarm-jax-cache-$$
rm -rf "$cache"
args=(--impl jax --segments 10 --batches 32768 --seconds 2)
echo "$(nproc) cores; $(nvidia-smi -L 2>/dev/null | head -1)"
for run in first second; do
  SOFTARM_JAX_CACHE=$cache $PY -m bench.throughput "${args[@]}" \
    --label "cache on, $run process" --out "$OUT/cache_$run" || exit 1
done
SOFTARM_JAX_CACHE=0 $PY -m bench.throughput "${args[@]}" --label "cache off" --out "$OUT/cache_off"
echo "cache files: $(find "$cache" -type f | wc -l), $(du -sh "$cache" | cut -f1)"
