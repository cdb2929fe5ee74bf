#!/usr/bin/env bash
# Runs ON THE GPU MACHINE (the device tool's `run`), from the repository root of the copy sent there.
#
#   bash tools/device/throughput.sh [bench/throughput.py arguments...]
#
# Every call: (1) stages what the call carried: .whl/ -> /tmp/whl/, .whl-warpN/ -> /tmp/wp/;
# (2) installs the mujoco wheels once (sha256 checked) with
#     pip install --no-index --no-deps --target /tmp/site;
# (3) once /tmp/wp holds every piece of the warp-lang wheel (the joined file's sha256 matches),
#     installs it the same way; (4) with arguments, runs `python -m bench.throughput ARGS --append
#     --out /tmp/bench_out` under `timeout` and puts the results into $OUT: the .md, .json and
#     check-pose .npz, the log, and everything as bench_out.tar.gz.
# /tmp stays as a call left it for the next call while the machine is warm (30 s after a call
# ends), so results of successive calls accumulate in /tmp/bench_out (one table) and the warp
# pieces add up in /tmp/wp. A fresh machine starts bare: then start again from call 1.
#
# Prepare HERE first: `bash tools/device/fetch_wheels.sh` (writes the git-ignored .whl/,
# .whl-warp1/ ... .whl-warp4/; it prints the piece count). A call sends the working tree (~25 MiB)
# plus its carried paths, 64 MiB in all, hence one folder per call. Exact sequence of `run` calls
# (kind nvidia-h100-x1, or nvidia-h200; calls 2-5 must each start within the 30 s warm window):
#
#   1. carry [".whl"], timeout_s 600:
#        bash tools/device/throughput.sh --impl jax --segments 10 20 30 --batches 8192 32768 --seconds 2
#      (installs mujoco; MuJoCo C and MJX-JAX for every segment count; results come back)
#   2. carry [".whl-warp1"], timeout_s 120:   bash tools/device/throughput.sh
#   3. carry [".whl-warp2"], timeout_s 120:   bash tools/device/throughput.sh
#   4. carry [".whl-warp3"], timeout_s 120:   bash tools/device/throughput.sh
#   5. carry [".whl-warp4"], timeout_s 600:
#        bash tools/device/throughput.sh --impl warp --segments 10 20 30 --batches 8192 32768 --seconds 2
#      (joins and installs warp-lang; MJX-Warp, checked against the MJX-JAX poses of call 1;
#      the returned throughput_segments.{md,json} hold both implementations)
#
# If the machine was lost between calls (the script then reports missing pieces or no mujoco),
# carry ".whl" together with no piece and begin again. To merge results of two machines' runs
# here: python -m bench.throughput --report-only --segments 10 20 30 --out DIR --merge OTHER.json
# BENCH_TIMEOUT_S (default 540) bounds the benchmark so that the results still reach $OUT; the
# tables are rewritten after every row, so a run stopped part-way returns what it measured, and a
# later call (--segments of what is missing) adds the rest to the same table.
# Run on one H100 (2026-11-23; bench/results/h100/throughput_segments.md): call 1 with all three
# segment counts needs more than the 540 s bound (MJX-JAX compiles 47-148 s per program), so it
# stopped before 30 segments at 32,768; the machine was then lost, so the warp pieces went to a
# fresh machine and .whl followed them in a call of its own (.whl and a piece do not fit one call).
# Split call 1 as --segments 10 20, then --segments 30. The Warp call needs ~10 min for 20 and 30.
set -uo pipefail

source "$(dirname "${BASH_SOURCE[0]}")/install.sh" || exit 1
STATE=$TMP/bench_out
mkdir -p "$STATE"

# (4) The benchmark.
(($# == 0)) && exit 0
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader || true
timeout -k 15 "${BENCH_TIMEOUT_S:-540}" $PY -m bench.throughput "$@" --append --out "$STATE" 2>&1 |
  tee -a "$STATE/log.txt"
rc=$?
cp -f "$STATE"/*.md "$STATE"/*.json "$STATE"/*.npz "$STATE"/log.txt "$OUT/" 2>/dev/null
tar -czf "$OUT/bench_out.tar.gz" -C "$(dirname "$STATE")" "$(basename "$STATE")"
echo "benchmark exit status $rc; in \$OUT: $(ls "$OUT" | tr '\n' ' ')"
exit $rc
