# Sourced HERE (tools/device/fetch_wheels.sh, cut_wheels.sh) and ON THE GPU MACHINE
# (tools/device/install.sh, tools/device/chain.sh): what travels in a device `run` call, and files
# that travel cut into pieces over several calls (the wheels, a run's state).

# Bytes that travel with every call: tracked files plus untracked files git does not ignore.
tree_bytes() {
  { git ls-files -z; git ls-files -z -o --exclude-standard; } |
    xargs -0 -r stat -c %s -- 2>/dev/null | awk '{s += $1} END {print s + 0}'
}

# check_sum FILE SUMS: 0 when SUMS is one line '<sha256>  NAME' (sha256sum's format), NAME is
# FILE's own name with no folder, and FILE's sha256 is that one; else 1, saying why on stderr.
# (`sha256sum -c SUMS` would check whatever file SUMS names, an absolute path included: a good
# file elsewhere would then vouch for a corrupt FILE.)
check_sum() {
  local file=$1 sums=$2 name line want have re='^([0-9a-f]{64}) [ *](.*)$'
  name=$(basename "$file")
  line=$(cat "$sums" 2>/dev/null) || { echo "no $sums" >&2; return 1; }
  if [[ $line == *$'\n'* || ! $line =~ $re ]]; then
    echo "$sums is not one line '<sha256>  $name'" >&2
    return 1
  fi
  want=${BASH_REMATCH[1]}
  if [[ ${BASH_REMATCH[2]} != "$name" ]]; then
    echo "$sums names '${BASH_REMATCH[2]}', not the file beside it, $name (no folder)" >&2
    return 1
  fi
  have=$(sha256sum <"$file" | cut -d' ' -f1)
  if [[ $have != "$want" ]]; then
    echo "$name does not match its sha256 in $sums" >&2
    return 1
  fi
}

# join_pieces DIR FILE SUMS WHAT: joins DIR/FILE.part-* into DIR/FILE once DIR holds as many as
# DIR/n_pieces says, and checks it against DIR/SUMS (sha256sum's format). Returns 0 when joined
# and checked, 1 while pieces are missing, 2 when the joined file does not match (then removed).
join_pieces() {
  local dir=$1 file=$2 sums=$3 what=$4 want have
  want=$(cat "$dir/n_pieces" 2>/dev/null || echo 0)
  have=$(compgen -G "$dir/$file.part-*" | wc -l)
  if ((have != want)); then
    echo "$what pieces staged so far: $have of $want"
    return 1
  fi
  cat "$dir/$file".part-* >"$dir/$file"
  if ! check_sum "$dir/$file" "$dir/$sums" >/dev/null 2>&1; then
    rm -f "$dir/$file"
    echo "the joined $what pieces do not match their sha256"
    return 2
  fi
}
