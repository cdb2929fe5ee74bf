#!/usr/bin/env bash
# Runs ON THE GPU MACHINE: one study, `bash studies/device.sh NAME [ARGS...]` runs
# `python -m studies.NAME ARGS --out $OUT/NAME` (bench/device/module.sh gives the call sequence;
# with no NAME it only installs).
source "$(dirname "${BASH_SOURCE[0]}")/../bench/device/module.sh" ${1:+"studies.$1"} "${@:2}"
