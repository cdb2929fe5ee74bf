# Sourced HERE (bench/device/fetch_wheels.sh, cut_wheels.sh) and ON THE GPU MACHINE
# (bench/device/install.sh, experiments/device.sh): what travels in a device `run` call, and files
# that travel cut into pieces over several calls (the wheels, a run's state).

# Bytes that travel with every call: tracked files plus untracked files git does not ignore.
tree_bytes() {
  { git ls-files -z; git ls-files -z -o --exclude-standard; } |
    xargs -0 -r stat -c %s -- 2>/dev/null | awk '{s += $1} END {print s + 0}'
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
  if ! (cd "$dir" && sha256sum -c --quiet "$sums" >/dev/null 2>&1); then
    rm -f "$dir/$file"
    echo "the joined $what pieces do not match their sha256"
    return 2
  fi
}
