#!/usr/bin/env bash
# Downloads, HERE (a machine with PyPI), the wheels that bench/throughput.py needs on a GPU machine
# that has Python 3.12 + jax 0.11 (CUDA) but no mujoco and no network, and cuts them into loads
# that each fit one device `run` call.
#
#   bash tools/device/fetch_wheels.sh            # piece size from the working tree's size
#   PIECE_MIB=30 bash tools/device/fetch_wheels.sh
#
# Writes (all git-ignored, see .gitignore):
#   .whl/            mujoco 3.17.0 (without MuJoCo Studio, see below), mujoco-mjx 3.17.0 and the
#                    three needs the GPU image lacks (glfw, pyopengl, trimesh); ~22 MiB, one
#                    call's load beside the ~39 MiB tree; SHA256SUMS beside them.
#   .whl-warp/       the whole warp-lang 1.18.0 wheel (~142 MiB; never carried) and its SHA256SUMS.
#   .whl-warp1/ ...  the wheel cut with `split` into pieces (.part-aa, .part-ab, ...), one folder
#                    per call, each with a copy of SHA256SUMS.
#
# Why pieces: a `run` call sends the working tree (tracked and untracked-not-ignored files, about
# 25 MiB in 2026-11) plus its carried paths, 64 MiB in all. What is left for a carried folder sets
# the piece size (64 MiB - tree - 2 MiB margin, at most 48 MiB); with a 25 MiB tree the warp wheel
# takes 4 pieces. tools/device/throughput.sh puts them back together on the device.
#
# Versions: the project pins mujoco==3.17.0 and mujoco-mjx==3.17.0 (pyproject.toml); mujoco-mjx
# 3.17's `warp` extra pins warp-lang==1.18.0. The GPU image already has absl-py, etils, scipy,
# numpy and typing-extensions, which mujoco and mujoco-mjx also need. glfw, pyopengl and trimesh
# are the versions of the project's test environment.
set -euo pipefail
cd "$(git rev-parse --show-toplevel)"

MUJOCO_WHEELS=(mujoco==3.17.0 mujoco-mjx==3.17.0 glfw==2.11.0 pyopengl==3.1.10 trimesh==5.2.0)
WARP_WHEEL=warp-lang==1.18.0
PIP_TARGET=(--no-deps --only-binary=:all: --python-version 3.12 --implementation cp
  --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64
  --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform any)

download() {  # folder, requirements...
  local dir=$1
  shift
  mkdir -p "$dir"
  python3 -m pip download -q "${PIP_TARGET[@]}" -d "$dir" "$@"
  (cd "$dir" && sha256sum -- *.whl >SHA256SUMS)
}

rm -rf .whl .whl-warp .whl-warp[0-9]*
mkdir -p .whl
python3 -m pip download -q "${PIP_TARGET[@]}" -d .whl "${MUJOCO_WHEELS[@]}"
# mujoco's wheel carries MuJoCo Studio (mujoco/experimental: a GUI, 15 of its 27 MB), which
# nothing here imports: without it the tree, the wheels of one call and the tree fit 64 MiB.
zip -q -d .whl/mujoco-*.whl 'mujoco/experimental/*'
(cd .whl && sha256sum -- *.whl >SHA256SUMS)
download .whl-warp "$WARP_WHEEL"

source tools/device/pieces.sh
tree_bytes=$(tree_bytes)
tree_mib=$(( (tree_bytes + 1048575) / 1048576 ))
piece_mib=${PIECE_MIB:-$(( 64 - tree_mib - 2 ))}
(( piece_mib > 48 )) && piece_mib=48
if (( piece_mib < 8 )); then
  echo "working tree is ${tree_mib} MiB: too little room left for pieces" >&2
  exit 1
fi

wheel=$(cd .whl-warp && ls -- *.whl)
split -b "${piece_mib}M" -a 2 ".whl-warp/$wheel" ".whl-warp/$wheel.part-"
i=0
for part in .whl-warp/"$wheel".part-*; do
  i=$((i + 1))
  mkdir -p ".whl-warp$i"
  mv -- "$part" ".whl-warp$i/"
  cp .whl-warp/SHA256SUMS ".whl-warp$i/"
done

whl_mib=$(du -sm .whl | cut -f1)
echo "working tree ${tree_mib} MiB; .whl ${whl_mib} MiB; warp wheel in $i pieces of <= ${piece_mib} MiB"
(( tree_mib + whl_mib > 64 )) && echo "WARNING: .whl does not fit one call beside the tree" >&2
du -sm .whl .whl-warp[0-9]*
