"""tools/device/distill_schedule.sh, rehearsed off the GPU: a stand-in Python records each command
and writes what ccgan.distill would, so the script's run names, teacher caches, resumes and
returned files are checked without a device."""

import os
import shutil
import subprocess
import tarfile

from experiments import paper

#: Stands in for python on the device: logs its arguments; as ccgan.distill, writes a finished
#: run (distill.json) and the teacher cache into --out.
FAKE_PYTHON = """#!/usr/bin/env bash
echo "$*" >> "$CALLS"
[[ $1 == -m && $2 == ccgan.distill ]] || exit 0
while [[ $# -gt 0 ]]; do [[ $1 == --out ]] && out=$2; shift; done
mkdir -p "$out" && echo '{"history": {"complete": true}}' > "$out/distill.json"
touch "$out/teacher.npz" "$out/translator.ckpt"
"""


def _device(tmp_path):
    """The tree as the device sees it: the script, a stand-in install.sh, a carried cache."""
    device = tmp_path / "device"
    (device / "tools" / "device").mkdir(parents=True)
    shutil.copy(
        paper.REPO / "tools" / "device" / "distill_schedule.sh", device / "tools" / "device"
    )
    (device / "tools" / "device" / "install.sh").write_text(
        'TMP=$DEVICE_TMP; OUT=$TMP/out; mkdir -p "$OUT"\n'
    )
    (device / ".teacher_cache" / "c").mkdir(parents=True)
    (device / ".teacher_cache" / "c" / "teacher.npz").write_bytes(b"chain teacher")
    python = tmp_path / "python"
    python.write_text(FAKE_PYTHON)
    python.chmod(0o755)
    env = os.environ | {
        "DEVICE_TMP": str(tmp_path / "tmp"),
        "PY": str(python),
        "CALLS": str(tmp_path / "calls.txt"),
    }
    return device, env


def _call(device, env, *runs):
    return subprocess.run(
        ["bash", "tools/device/distill_schedule.sh", *runs],
        cwd=device,
        env=env,
        capture_output=True,
        text=True,
    )


def test_runs_take_the_carried_cache_at_the_chains_k_and_plan_their_own_elsewhere(tmp_path):
    device, env = _device(tmp_path)
    call = _call(device, env, "aged_k25_b80_e1840", "c_b80_e560")
    assert call.returncode == 0, call.stderr
    distills = [
        line
        for line in (tmp_path / "calls.txt").read_text().splitlines()
        if "ccgan.distill" in line
    ]
    aged, c = distills
    assert "--domain aged" in aged and "--hold-factor 25" in aged and "--teacher-from" not in aged
    assert "--batch-size 80 --epochs 1840 --eval-every 920" in aged
    assert "--hold-factor 15" in c and "--teacher-from" in c and "/cache/c/teacher.npz" in c
    out = tmp_path / "tmp" / "out"
    assert (out / "teacher_aged_k25_b80_e1840.npz").exists()  # its own teacher comes back
    assert not (out / "teacher_c_b80_e560.npz").exists()  # the carried one does not
    with tarfile.open(out / "distill_schedule.tar.gz") as tar:
        names = tar.getnames()
    assert "distill_schedule/c_b80_e560/distill.json" in names
    assert not [n for n in names if n.endswith("teacher.npz") or "/cache" in n]

    again = _call(device, env, "c_b80_e560")
    assert again.returncode == 0 and "c_b80_e560: done before" in again.stdout
    assert (tmp_path / "calls.txt").read_text().count("ccgan.distill") == 2


def test_a_bad_run_name_is_refused_before_anything_runs(tmp_path):
    device, env = _device(tmp_path)
    call = _call(device, env, "c_b80")
    assert call.returncode == 2 and "bad run name c_b80" in call.stderr
    assert "ccgan.distill" not in (tmp_path / "calls.txt").read_text()
