#!/usr/bin/env bash
# Cuts .whl/ (tools/device/fetch_wheels.sh) HERE into loads that each travel beside the working
# tree in one device `run` call (64 MiB a call, tree included), for a tree too large to travel
# beside the whole .whl (about 22 MiB).
#
#   bash tools/device/cut_wheels.sh       # as many pieces as the tree's size needs
#   PIECES=4 bash tools/device/cut_wheels.sh
#
# Writes .whl-extra1/ ... .whl-extraN/ (git-ignored), each holding one byte piece of a tar of
# .whl (wheels.tar.part-aa, -ab, ...), the tar's sha256 (wheels.sha256) and the piece count
# (n_pieces). tools/device/install.sh stages each carried piece in $TMP and, once all N have
# come over consecutive calls on one warm machine and the joined tar matches its sha256, unpacks
# and installs the wheels.
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"
[[ -f .whl/SHA256SUMS ]] || { echo "no .whl/: run tools/device/fetch_wheels.sh first" >&2; exit 1; }

source tools/device/pieces.sh
tree_bytes=$(tree_bytes)
limit=$((64 * 1048576))
margin=$((2 * 1048576)) # room for what a call carries beside a piece (a translator, a state)
room=$((limit - tree_bytes - margin))
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
tar -cf "$tmp/wheels.tar" -C .whl .
size=$(stat -c %s "$tmp/wheels.tar")
if [[ -n ${PIECES:-} ]]; then
  pieces=$PIECES
else
  ((room > 1048576)) || { echo "the tree (${tree_bytes} bytes) leaves no room for pieces" >&2; exit 1; }
  pieces=$(((size + room - 1) / room))
fi
piece=$(((size + pieces - 1) / pieces))
((piece <= room)) || echo "WARNING: pieces of ${piece} bytes do not fit beside the tree (${room})" >&2
(cd "$tmp" && sha256sum wheels.tar >wheels.sha256)
split -b "$piece" -a 2 "$tmp/wheels.tar" "$tmp/wheels.tar.part-"
rm -rf .whl-extra[0-9]*
i=0
for part in "$tmp"/wheels.tar.part-*; do
  i=$((i + 1))
  mkdir -p ".whl-extra$i"
  mv -- "$part" ".whl-extra$i/"
  cp "$tmp/wheels.sha256" ".whl-extra$i/"
  echo "$pieces" >".whl-extra$i/n_pieces"
done
echo "tree $((tree_bytes / 1048576)) MiB; .whl as $i piece(s) of <= $((piece / 1048576 + 1)) MiB:" \
  "carry .whl-extra1 ... .whl-extra$i, one per call"
