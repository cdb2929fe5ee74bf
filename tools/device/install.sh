# Sourced ON THE GPU MACHINE by tools/device/throughput.sh and tools/device/chain.sh, from the
# repository root of the copy sent there: installs what the call carried, no network needed.
#
# (1) stages the carried wheel folders: .whl/ or, for a tree too large to travel beside the whole
#     .whl, its pieces .whl-extra1/ ... .whl-extraN/ (tools/device/cut_wheels.sh; or whole wheels
#     in two halves, as before), carried in consecutive calls while the machine stays warm
#     -> $TMP/whl/, .whl-warpN/ -> $TMP/wp/;
# (2) installs the mujoco wheels once (sha256 checked) with
#     pip install --no-index --no-deps --target $TMP/site;
# (3) once $TMP/wp holds every piece of the warp-lang wheel (the joined file's sha256 matches),
#     installs it the same way; (4) the wheels of .whl-optuna; then prints the versions it sees.
# Sets SITE, OUT, PY, PYTHONPATH, MUJOCO_GL=disable and PYTHONUNBUFFERED for the caller.
# $TMP stays as a call left it while the machine is warm (30 s after a call ends); a fresh
# machine starts bare. Wheels come from tools/device/fetch_wheels.sh, run here first.
TMP=${DEVICE_TMP:-/tmp} # overridable only to rehearse the calls on another machine
SITE=$TMP/site
WHL=$TMP/whl
WP=$TMP/wp
OUT=${OUT:-$TMP/out}
PY=${PY:-python3}
mkdir -p "$SITE" "$WHL" "$WP" "$OUT"
source "$(dirname "${BASH_SOURCE[0]}")/pieces.sh" || exit 1
export PYTHONPATH="$SITE:$PWD"
export MUJOCO_GL=disable # no rendering here; keeps mujoco from loading EGL/OpenGL
export PYTHONUNBUFFERED=1

# (1) Stage what this call carried.
if compgen -G ".whl/*.whl" >/dev/null; then
  cp -f .whl/* "$WHL/"
  echo "staged $(ls .whl/*.whl | wc -l) mujoco wheels"
fi
# .whl cut for a tree too large to travel beside the whole .whl, staged call by call: either
# whole wheels (.whl-extra1, .whl-extra2, each with a copy of SHA256SUMS), or byte pieces of a tar
# of .whl (tools/device/cut_wheels.sh: wheels.tar.part-*, wheels.sha256, n_pieces), unpacked into
# $WHL once all pieces are here and the joined tar matches its sha256.
for dir in .whl-extra[0-9]*; do
  [[ -d $dir ]] || continue
  if compgen -G "$dir/wheels.tar.part-*" >/dev/null; then
    mkdir -p "$TMP/whl_parts" && cp -f "$dir"/* "$TMP/whl_parts/"
    echo "staged wheel piece(s) $(cd "$dir" && ls -- wheels.tar.part-* | tr '\n' ' ')from $dir"
  else
    cp -f "$dir"/* "$WHL/"
    echo "staged $(ls "$dir"/*.whl | wc -l) mujoco wheel(s) from $dir"
  fi
done
if [[ -f $TMP/whl_parts/wheels.sha256 ]] && ! compgen -G "$WHL/*.whl" >/dev/null; then
  join_pieces "$TMP/whl_parts" wheels.tar wheels.sha256 wheel
  case $? in
  0) tar -xf "$TMP/whl_parts/wheels.tar" -C "$WHL" && rm -f "$TMP/whl_parts/wheels.tar" ;;
  2) exit 1 ;;
  esac
fi
for dir in .whl-warp[0-9]*; do
  [[ -d $dir ]] || continue
  cp -f "$dir"/* "$WP/"
  echo "staged $(ls "$dir" | grep -c part-) warp piece(s) from $dir"
done

# (2) mujoco, mujoco-mjx and their missing needs.
if ! $PY -c "import mujoco.mjx" >/dev/null 2>&1; then
  # (The check's output is read whole: grep -q in a pipe would end sha256sum early, and under a
  # caller's pipefail that SIGPIPE would read as "not missing".)
  check=$(cd "$WHL" 2>/dev/null && sha256sum -c SHA256SUMS 2>&1)
  if compgen -G "$WHL/*.whl" >/dev/null && [[ $check == *"No such file"* ]]; then
    echo "mujoco wheels staged so far: $(cd "$WHL" && ls -- *.whl | tr '\n' ' ')(not all yet)"
  elif compgen -G "$WHL/*.whl" >/dev/null; then
    (cd "$WHL" && sha256sum -c --quiet SHA256SUMS) || { echo "mujoco wheels: bad sha256"; exit 1; }
    $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
      --target "$SITE" "$WHL"/*.whl || exit 1
    echo "installed: $(cd "$WHL" && ls -- *.whl | tr '\n' ' ')"
  elif [[ ! -f $TMP/whl_parts/wheels.sha256 ]]; then
    echo "mujoco is not installed and no .whl was carried (machine fresh?): carry .whl"
  fi
fi

# (3) warp-lang, once all pieces are here.
if ! $PY -c "import warp" >/dev/null 2>&1 && [[ -f $WP/SHA256SUMS ]]; then
  wheel=$(awk '{print $2}' "$WP/SHA256SUMS")
  echo "warp pieces in $WP: $(cd "$WP" && ls -- *.part-* 2>/dev/null | sed 's/.*part-//' | tr '\n' ' ')"
  cat "$WP/$wheel".part-* >"$WP/$wheel"
  if (cd "$WP" && sha256sum -c --quiet SHA256SUMS >/dev/null 2>&1); then
    $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
      --target "$SITE" "$WP/$wheel" || exit 1
    rm -f "$WP/$wheel"
    echo "installed: $wheel"
  else
    rm -f "$WP/$wheel"
    echo "warp wheel not complete yet (sha256 of the joined pieces does not match)"
  fi
fi
# (4) optuna and its needs (not on the GPU image) when .whl-optuna was carried (pip download
#     optuna and matplotlib for Python 3.12 into it), each wheel installed unless already there.
if compgen -G ".whl-optuna/*.whl" >/dev/null; then
  for whl in .whl-optuna/*.whl; do
    name=$(basename "$whl" | cut -d- -f1 | tr '[:upper:]' '[:lower:]')
    $PY -c "import importlib.metadata as m; m.version('$name')" >/dev/null 2>&1 && continue
    # Into a folder of its own, then merged: mujoco-mjx adds mujoco/mjx to mujoco's folder.
    rm -rf "$TMP/one" && $PY -m pip install -q --no-index --no-deps --no-compile --target \
      "$TMP/one" "$whl" && cp -a "$TMP/one/." "$SITE/" || exit 1
  done
fi
$PY - <<'EOF'
from importlib import metadata
for d in ("jax", "jaxlib", "mujoco", "mujoco-mjx", "warp-lang", "numpy", "optuna"):
    try:
        print(f"  {d} {metadata.version(d)}")
    except metadata.PackageNotFoundError:
        print(f"  {d} -")
EOF

