"""The device helpers of tools/device/: the wheels cut into byte pieces (cut_wheels.sh) come back
whole there (install.sh) only once every piece has come, and a bad piece is refused; a run's state
returned in pieces is joined and kept here (take_state.sh) only when it matches its own sha256, and
cut into carryable pieces that chain.sh restores there; the machine line of the benches' result
files."""

import hashlib
import os
import shutil
import subprocess
import tarfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DEVICE = REPO / "tools" / "device"


def _repo_with_wheels(root: Path) -> dict[str, bytes]:
    """A git repository holding the two scripts and a .whl/ of two fake wheels (git-ignored)."""
    (root / "tools" / "device").mkdir(parents=True)
    for name in ("cut_wheels.sh", "install.sh", "pieces.sh"):
        shutil.copy(DEVICE / name, root / "tools" / "device")
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
        ["bash", "-c", "source tools/device/install.sh"],
        cwd=device,
        env=env,
        capture_output=True,
        text=True,
    )


def test_wheels_cut_into_pieces_are_joined_on_the_device_once_all_have_come(tmp_path):
    here = tmp_path / "here"
    wheels = _repo_with_wheels(here)
    script = here / "tools" / "device" / "cut_wheels.sh"
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
    (device / "tools" / "device").mkdir(parents=True)
    for name in ("install.sh", "pieces.sh"):
        shutil.copy(here / "tools" / "device" / name, device / "tools" / "device")
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


def _state_pieces(tmp_path):
    """(take(*args): runs a copy of tools/device/take_state.sh on a device call's files, the
    whole state's bytes, the folder of its pieces) for a run folder paper/ with one stage.json
    ({}); take_state.sh keeps the state in the copy's STATE_DIR .paper_state_rerun."""
    repo = tmp_path / "repo"
    (repo / "tools" / "device").mkdir(parents=True)
    for name in ("take_state.sh", "pieces.sh"):
        shutil.copy(DEVICE / name, repo / "tools" / "device")
    script = repo / "tools" / "device" / "take_state.sh"
    (tmp_path / "paper").mkdir()
    (tmp_path / "paper" / "stage.json").write_text("{}")
    whole = tmp_path / "paper_state.tar.gz"
    with tarfile.open(whole, "w:gz") as tar:
        tar.add(tmp_path / "paper", arcname="paper")
    blob = whole.read_bytes()
    files_at = tmp_path / "files"
    files_at.mkdir()
    half = len(blob) // 2
    (files_at / "paper_state.tar.gz.part-00").write_bytes(blob[:half])
    (files_at / "paper_state.tar.gz.part-01").write_bytes(blob[half:])
    digest = hashlib.sha256(blob).hexdigest()
    (files_at / "paper_state.sha256").write_text(f"{digest}  paper_state.tar.gz\n")
    env = os.environ | {"STATE_DIR": ".paper_state_rerun"}

    def take(*args):
        return subprocess.run(
            ["bash", str(script), str(files_at), *args], env=env, capture_output=True, text=True
        )

    return take, blob, files_at


def test_take_state_keeps_a_second_runs_state_apart_and_refuses_a_bad_join(tmp_path):
    """take_state.sh joins a device call's pieces into STATE_DIR only, leaving the first run's
    state as it was; pieces that do not match their sha256 change nothing."""
    take, blob, files_at = _state_pieces(tmp_path)
    repo = tmp_path / "repo"
    first = repo / ".paper_state" / "paper_state.tar.gz"
    first.parent.mkdir()
    first.write_bytes(b"the first run")
    half = len(blob) // 2
    done = take(str(tmp_path / "unpacked"))
    assert done.returncode == 0, done.stderr
    assert (repo / ".paper_state_rerun" / "paper_state.tar.gz").read_bytes() == blob
    assert (tmp_path / "unpacked" / "paper" / "stage.json").read_text() == "{}"
    assert first.read_bytes() == b"the first run"
    (files_at / "paper_state.tar.gz.part-01").write_bytes(blob[half:] + b"x")
    bad = take()
    assert bad.returncode == 1 and "does not match" in bad.stderr
    assert (repo / ".paper_state_rerun" / "paper_state.tar.gz").read_bytes() == blob


@pytest.mark.parametrize("named", ["absolute", "relative", "two lines"])
def test_take_state_checks_the_joined_file_itself_whatever_the_sha256_file_names(tmp_path, named):
    """A sha256 file that names another existing file (by absolute or relative path, or in a
    second line) cannot vouch for corrupt pieces: the kept good state stays, with an error that
    says why. (sha256sum -c checked whichever file the line named, and the corrupt join was then
    kept over the good state.)"""
    take, blob, files_at = _state_pieces(tmp_path)
    kept = tmp_path / "repo" / ".paper_state_rerun" / "paper_state.tar.gz"
    assert take().returncode == 0 and kept.read_bytes() == blob
    good = tmp_path / "files" / "good.tar.gz"  # an existing file whose sha256 is the line's
    good.write_bytes(blob)
    (files_at / "paper_state.tar.gz.part-01").write_bytes(b"corrupt")
    digest = hashlib.sha256(blob).hexdigest()
    line = {
        "absolute": f"{digest}  {good}\n",
        "relative": f"{digest}  ../files/good.tar.gz\n",
        "two lines": f"{digest}  {good}\n{digest}  paper_state.tar.gz\n",
    }[named]
    (files_at / "paper_state.sha256").write_text(line)
    bad = take()
    assert bad.returncode == 1
    assert "the kept state is unchanged" in bad.stderr
    assert "not the file beside it" in bad.stderr or "not one line" in bad.stderr
    assert kept.read_bytes() == blob


def test_take_state_never_unpacks_over_a_run_folder(tmp_path):
    """An older state unpacked where a run folder already is: refused before anything changes,
    the newer folder (and a user's file in it) as it was, the state not even kept."""
    take, _, _ = _state_pieces(tmp_path)
    newer = tmp_path / "unpacked" / "paper"
    (newer / "table").mkdir(parents=True)
    (newer / "table" / "stage.json").write_text('{"newer": true}')
    (newer / "notes.txt").write_text("mine")
    refused = take(str(tmp_path / "unpacked"))
    assert refused.returncode == 1
    assert "paper exists" in refused.stderr and "does not unpack over" in refused.stderr
    assert sorted(p.name for p in newer.iterdir()) == ["notes.txt", "table"]
    assert (newer / "table" / "stage.json").read_text() == '{"newer": true}'
    assert not (tmp_path / "repo" / ".paper_state_rerun").exists()
    done = take(str(tmp_path / "elsewhere"))  # beside it, on request
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "elsewhere" / "paper" / "stage.json").read_text() == "{}"


def test_state_cut_into_pieces_is_restored_on_the_device_once_every_piece_has_come(tmp_path):
    """take_state.sh --pieces N cuts the kept state into N carryable folders; chain.sh (RUN=0,
    call by call, each carrying one piece) stages them, restores nothing until the last has
    come, then restores the run folder; a piece that does not match the sha256 is refused."""
    take, blob, _ = _state_pieces(tmp_path)
    repo = tmp_path / "repo"
    assert take().returncode == 0  # keeps .paper_state_rerun/paper_state.tar.gz
    script = repo / "tools" / "device" / "take_state.sh"
    env = os.environ | {"STATE_DIR": ".paper_state_rerun"}
    bad = subprocess.run(["bash", str(script), "--pieces", "x"], env=env, capture_output=True)
    assert bad.returncode == 2
    cut = subprocess.run(
        ["bash", str(script), "--pieces", "3"], env=env, capture_output=True, text=True
    )
    assert cut.returncode == 0, cut.stderr
    pieces = sorted(repo.glob(".paper_state_rerun_part*"))
    assert [p.name[-1] for p in pieces] == ["1", "2", "3"]
    joined = b"".join(next(p.glob("*.part-*")).read_bytes() for p in pieces)
    assert joined == blob

    device = tmp_path / "device"  # the copy of the tree on the GPU machine
    (device / "tools" / "device").mkdir(parents=True)
    for name in ("chain.sh", "pieces.sh"):
        shutil.copy(DEVICE / name, device / "tools" / "device")
    (device / "tools" / "device" / "install.sh").write_text(
        'TMP=$DEVICE_TMP; OUT=$TMP/out; PY=python3; mkdir -p "$OUT"\n'
    )
    env = os.environ | {"DEVICE_TMP": str(tmp_path / "tmp"), "RUN": "0",
                        "STATE_DIR": ".paper_state_rerun"}  # fmt: skip
    run_folder = tmp_path / "tmp" / "paper"
    chain = ["bash", "tools/device/chain.sh"]
    for i, piece in enumerate(pieces):
        shutil.copytree(piece, device / piece.name)
        call = subprocess.run(chain, cwd=device, env=env, capture_output=True, text=True)
        assert call.returncode == 0, call.stderr
        shutil.rmtree(device / piece.name)  # the next call carries only its own piece
        if i < 2:
            assert f"{i + 1} of 3" in call.stdout and not run_folder.exists()
    assert "restored" in call.stdout
    assert (run_folder / "stage.json").read_text() == "{}"

    shutil.rmtree(run_folder)
    parts = tmp_path / "tmp" / "state_parts"
    (parts / "paper_state.tar.gz.part-01").write_bytes(b"garbage")
    call = subprocess.run(chain, cwd=device, env=env, capture_output=True, text=True)
    assert call.returncode == 1 and "do not match" in call.stdout
    assert not run_folder.exists()


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


def test_rod_tables_run_the_stages_commands_with_the_committed_chain_translators(tmp_path):
    device = tmp_path / "device"  # the copy of the tree on the GPU machine
    (device / "tools" / "device").mkdir(parents=True)
    shutil.copy(DEVICE / "rod_tables.sh", device / "tools" / "device")
    tmp = tmp_path / "tmp"
    stub = tmp_path / "python"  # records its arguments, writes the --out folder
    stub.write_text('#!/bin/bash\necho "$@" >>"$DEVICE_TMP/calls"\nmkdir -p "${@: -1}"\n')
    stub.chmod(0o755)
    (device / "tools" / "device" / "install.sh").write_text(
        f'TMP=$DEVICE_TMP; OUT=$TMP/out; PY={stub}; mkdir -p "$OUT"\n'
    )
    env = os.environ | {"DEVICE_TMP": str(tmp), "CHAIN_RUN": "chain"}
    script = ["bash", "tools/device/rod_tables.sh"]

    def call(which):
        return subprocess.run(
            script, cwd=device, env=env | {"WHICH": which}, capture_output=True, text=True
        )

    assert call("rod_tables").returncode == 2
    missing = call("rod_table_aged")
    assert missing.returncode == 1 and "chain/aged_sim/translator.ckpt" in missing.stdout
    for name in ("chain/aged_sim", "chain/ccgan_sim"):
        (device / name).mkdir(parents=True)
        (device / name / "translator.ckpt").write_text("")
    missing = call("rod_table rod_table_aged")  # the rod's trainings have not run
    assert missing.returncode == 1 and "rod_ccgan/translator.ckpt" in missing.stdout
    for name in ("rod_ccgan", "rod_wcgan"):
        (tmp / "paper" / name).mkdir(parents=True)
        (tmp / "paper" / name / "translator.ckpt").write_text("")
    (tmp / "paper" / "rod_tracker").mkdir()
    done = call("rod_table rod_table_aged")
    assert done.returncode == 0, done.stdout + done.stderr
    calls = (tmp / "calls").read_text().splitlines()
    assert len(calls) == 2 and all("-m eval.shapes --simulator rod" in c for c in calls)
    table = next(c for c in calls if "--target-domain" not in c)
    assert f"--caches-from {tmp}/paper/rod_tracker" in table
    aged = next(c for c in calls if "--target-domain aged" in c)
    assert "--distilled-path chain/aged_sim/translator.ckpt" in aged
    assert sorted(p.name for p in (tmp / "out").iterdir()) == [
        "rod_tables_rod_table.tar.gz",
        "rod_tables_rod_table_aged.tar.gz",
    ]
