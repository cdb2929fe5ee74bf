"""The device helpers: the wheels cut into byte pieces (bench/device/cut_wheels.sh) come back
whole there (bench/device/install.sh) only once every piece has come, and a bad piece is refused;
the machine line of the benches' result files."""

import hashlib
import os
import shutil
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _repo_with_wheels(root: Path) -> dict[str, bytes]:
    """A git repository holding the two scripts and a .whl/ of two fake wheels (git-ignored)."""
    (root / "bench" / "device").mkdir(parents=True)
    for name in ("cut_wheels.sh", "install.sh", "pieces.sh"):
        shutil.copy(REPO / "bench" / "device" / name, root / "bench" / "device")
    (root / ".gitignore").write_text("/.whl*/\n")
    wheels = {
        "a-1.0-py3-none-any.whl": os.urandom(5000),
        "b-2.0-py3-none-any.whl": os.urandom(3001),
    }
    (root / ".whl").mkdir()
    sums = []
    for name, blob in wheels.items():
        (root / ".whl" / name).write_bytes(blob)
        sums.append(f"{hashlib.sha256(blob).hexdigest()}  {name}")
    (root / ".whl" / "SHA256SUMS").write_text("\n".join(sums) + "\n")
    subprocess.run(["git", "init", "-q"], cwd=root, check=True)
    subprocess.run(["git", "add", "."], cwd=root, check=True)
    return wheels


def _call(device: Path, tmp: Path, stub_python: Path) -> subprocess.CompletedProcess:
    """One device call: install.sh sourced in the copy of the tree, as the device scripts do."""
    env = os.environ | {"DEVICE_TMP": str(tmp), "PY": str(stub_python)}
    return subprocess.run(
        ["bash", "-c", "source bench/device/install.sh"],
        cwd=device,
        env=env,
        capture_output=True,
        text=True,
    )


def test_wheels_cut_into_pieces_are_joined_on_the_device_once_all_have_come(tmp_path):
    here = tmp_path / "here"
    wheels = _repo_with_wheels(here)
    script = here / "bench" / "device" / "cut_wheels.sh"
    one = subprocess.run(["bash", str(script)], cwd=here, capture_output=True, text=True)
    assert one.returncode == 0, one.stderr
    assert sorted(p.name for p in here.glob(".whl-extra*")) == [".whl-extra1"]  # a tiny tree
    cut = subprocess.run(
        ["bash", str(script)], cwd=here, env=os.environ | {"PIECES": "3"}, capture_output=True
    )
    assert cut.returncode == 0, cut.stderr
    pieces = sorted(here.glob(".whl-extra*"))
    assert [p.name for p in pieces] == [".whl-extra1", ".whl-extra2", ".whl-extra3"]

    # The device: a stub Python that says mujoco is there, so only the staging is exercised.
    stub = tmp_path / "python"
    stub.write_text("#!/bin/sh\nexit 0\n")
    stub.chmod(0o755)
    device, tmp = tmp_path / "device", tmp_path / "tmp"
    (device / "bench" / "device").mkdir(parents=True)
    for name in ("install.sh", "pieces.sh"):
        shutil.copy(here / "bench" / "device" / name, device / "bench" / "device")
    staged = tmp / "whl"
    for i, piece in enumerate(pieces):
        shutil.copytree(piece, device / piece.name)
        call = _call(device, tmp, stub)
        assert call.returncode == 0, call.stdout + call.stderr
        shutil.rmtree(device / piece.name)  # the next call carries only its own piece
        if i < 2:
            assert f"{i + 1} of 3" in call.stdout and not list(staged.glob("*.whl"))
    for name, blob in wheels.items():
        assert (staged / name).read_bytes() == blob

    # A piece that does not match the tar's sha256 is refused, and nothing is unpacked.
    shutil.rmtree(staged)
    parts = tmp / "whl_parts"
    (parts / "wheels.tar.part-ab").write_bytes(b"garbage")
    shutil.copytree(pieces[0], device / pieces[0].name)
    call = _call(device, tmp, stub)
    assert call.returncode == 1 and "do not match" in call.stdout
    assert not list(staged.glob("*.whl"))


def test_run_header_names_a_cpu_once_and_a_gpu_by_its_kind(monkeypatch):
    """The header's device line: "cpu" on a CPU (not "cpu: cpu"), "gpu: <kind>" on a GPU."""
    import jax

    import bench

    class Device:
        def __init__(self, platform, kind):
            self.platform, self.device_kind = platform, kind

    monkeypatch.setattr(jax, "devices", lambda: [Device("cpu", "cpu")])
    assert bench.run_header("bench.x", ["--a"])["device"] == "cpu"
    monkeypatch.setattr(jax, "devices", lambda: [Device("gpu", "NVIDIA H100 80GB HBM3")])
    header = bench.run_header("bench.x", ["--a"])
    assert header["device"] == "gpu: NVIDIA H100 80GB HBM3"
    assert header["command"] == "python -m bench.x --a"
