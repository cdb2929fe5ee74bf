#!/usr/bin/env bash
# Runs HERE, after a call of tools/device/chain.sh: joins the returned pieces of the run folder
# (paper_state.tar.gz.part-NN), checks them against paper_state.sha256 and keeps the whole file
# as .paper_state/paper_state.tar.gz, which the next call restores from on a fresh machine.
# STATE_DIR=.paper_state_NAME keeps a second run's state apart from the first (tools/device/chain.sh
# reads the same variable).
#
#   bash tools/device/take_state.sh FILES_AT          # FILES_AT: the folder the call's files lie in
#   bash tools/device/take_state.sh FILES_AT runs/    # and unpack the run folder into runs/paper
# It never unpacks over a run folder: with UNPACK_DIR/paper already there it refuses before
# doing anything (move that folder away, or name another UNPACK_DIR).
#   bash tools/device/take_state.sh --pieces N       # cut the kept state into N carryable folders
# --pieces N: .paper_state_part1/ ... .paper_state_partN/, each with a piece of the kept file,
# paper_state.sha256 and n_pieces, for a state that does not travel beside the tree in one call
# (tools/device/chain.sh stages the pieces call by call and restores once all are there).
set -euo pipefail
here=$(dirname "${BASH_SOURCE[0]}")
root=$(cd "$here/../.." && pwd)
source "$here/pieces.sh" # check_sum
if [[ ${1:-} == --pieces ]]; then
  n=${2:?usage: take_state.sh --pieces N}
  [[ $n =~ ^[1-9][0-9]?$ ]] || { echo "--pieces takes a number from 1 to 99, got $n" >&2; exit 2; }
  state_dir=$root/${STATE_DIR:-.paper_state}
  whole=$state_dir/paper_state.tar.gz
  [[ -f $whole ]] || { echo "no $whole to cut" >&2; exit 1; }
  rm -rf "$state_dir"_part[0-9]*
  size=$(stat -c %s "$whole")
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  split -n "$n" -d -a 2 "$whole" "$tmp/paper_state.tar.gz.part-"
  i=1
  for piece in "$tmp"/paper_state.tar.gz.part-*; do
    mkdir -p "$state_dir"_part$i
    mv "$piece" "$state_dir"_part$i/
    (cd "$state_dir" && sha256sum paper_state.tar.gz) >"$state_dir"_part$i/paper_state.sha256
    echo "$n" >"$state_dir"_part$i/n_pieces
    i=$((i + 1))
  done
  echo "cut $(numfmt --to=iec "$size") into $n pieces: $(cd "$root" && ls -d "${STATE_DIR:-.paper_state}"_part* | tr '\n' ' ')"
  exit 0
fi
from=$(cd "${1:?usage: take_state.sh FILES_AT [UNPACK_DIR]}" && pwd)
if [[ -n ${2:-} && ( -e $2/paper || -L $2/paper ) ]]; then
  echo "$2/paper exists: take_state.sh does not unpack over a run folder; nothing was changed." \
    "Move it away or name another UNPACK_DIR" >&2
  exit 1
fi
compgen -G "$from/paper_state.tar.gz.part-*" >/dev/null || {
  echo "no paper_state.tar.gz.part-* in $from" >&2
  exit 1
}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cat "$from"/paper_state.tar.gz.part-* >"$tmp/paper_state.tar.gz"
# The sha256 file may name only the joined file (paper_state.tar.gz, no folder): see check_sum.
check_sum "$tmp/paper_state.tar.gz" "$from/paper_state.sha256" || {
  echo "the joined state does not match $from/paper_state.sha256: the kept state is unchanged" >&2
  exit 1
}
state_dir=$root/${STATE_DIR:-.paper_state}
mkdir -p "$state_dir"
mv -f "$tmp/paper_state.tar.gz" "$state_dir/paper_state.tar.gz"
echo "kept $(du -h "$state_dir/paper_state.tar.gz" | cut -f1) in $state_dir/"
if [[ -n ${2:-} ]]; then
  # Only the run folder paper/: no member outside it, and none over an existing file.
  members=$(tar -tzf "$state_dir/paper_state.tar.gz")
  if grep -qvE '^(\./)?paper(/|$)' <<<"$members"; then
    echo "the state holds files outside paper/: not unpacked" >&2
    exit 1
  fi
  mkdir -p "$2"
  tar -xzf "$state_dir/paper_state.tar.gz" -C "$2" --keep-old-files
  echo "unpacked into $2/paper"
fi
