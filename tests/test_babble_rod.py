"""Babbling in the reference rod (`python -m mjx_arm.babble --backend rod`): the chain's programs
and files, the rod's poses and labels; its batches; its refusals. Tiny sets (1 s programs)."""

import mjx_arm  # noqa: I001  (before jax: it sets an XLA CPU flag)

import json

import numpy as np
import pytest

from mjx_arm import babble, dataset
from mjx_arm.babble import cli as babble_cli
from mjx_arm.babble import rod as rod_babble
from mjx_arm.programs import babble_programs


@pytest.fixture(scope="module")
def rod_folder(tmp_path_factory):
    """A rod run of 2 + 1 programs of 1 s in both domains, written by the command line."""
    out = tmp_path_factory.mktemp("rod") / "babble"
    argv = ["--backend", "rod", "--n", "2", "--n-val", "1", "--duration", "1", "--seed", "3"]
    assert babble_cli.main([*argv, "--out", str(out), "--no-progress"]) == 0
    return out


@pytest.mark.parametrize("domain", ["source", "constrained"])
def test_rod_files_hold_the_chains_programs_and_the_rods_poses(rod_folder, domain):
    rod = mjx_arm.load_rod(domain)
    config = babble.BabbleConfig(n_train=2, n_val=1, duration_s=1.0, seed=3)
    for split, n in (("train", 2), ("val", 1)):
        ds = dataset.load_dataset(rod_folder / f"{domain}_{split}.npz")
        # The same programs as the chain's backends babble (seed, domain and split streams).
        np.testing.assert_array_equal(
            ds.pressures_bar, babble_programs(config, np.arange(n), domain=domain, split=split)
        )
        # The rod's poses of the written programs, to float32 storage.
        want = rod.rollout(ds.pressures_bar.astype(np.float64))
        np.testing.assert_allclose(ds.poses, want, rtol=0, atol=2e-7)
        assert ds.model_hash == rod.model_hash and ds.model_hash.startswith("rod-")
        assert ds.domain == domain and ds.config["simulator"] == "rod"
    # The two domains differ (D_c is ten times the damping): not one simulation written twice.
    other = "source" if domain == "constrained" else "constrained"
    a, b = (dataset.load_dataset(rod_folder / f"{d}_train.npz").poses for d in (domain, other))
    assert np.abs(a - b).max() > 1e-3


def test_the_manifest_names_the_rod(rod_folder):
    manifest = json.loads((rod_folder / dataset.MANIFEST_NAME).read_text())
    assert manifest["model_hash"] == mjx_arm.load_rod("constrained").model_hash
    assert manifest["config"]["backend"] == "rod"
    assert manifest["config"]["simulator"] == "rod"
    assert manifest["config"]["rod_dtype"] == "float64"
    assert manifest["model_hash"] != mjx_arm.load().model_hash
    assert sorted(manifest["files"]) == [
        f"{d}_{s}.npz" for d in ("constrained", "source") for s in ("train", "val")
    ]


def test_batches_one_call_on_a_gpu_small_chunks_on_a_cpu(monkeypatch):
    gpu = dict(on_accelerator=True)
    assert rod_babble.batch_sizes(400, 4096, **gpu) == [400]  # the long D_c set: one call
    assert rod_babble.batch_sizes(1000, 4096, **gpu) == [500, 500]
    assert rod_babble.batch_sizes(1025, 4096, **gpu) == [342, 342, 341]
    assert rod_babble.batch_sizes(53, 8, **gpu) == [8] * 6 + [5]
    monkeypatch.setenv("SOFTARM_THREADS", "2")
    assert rod_babble.batch_sizes(10, 4096, on_accelerator=False) == [4, 4, 2]
    assert rod_babble.batch_sizes(10, 3, on_accelerator=False) == [3, 3, 3, 1]
    assert rod_babble.batch_sizes(0, 4, on_accelerator=False) == []
    # On the host's devices: calls of the rod's call size, the last shorter, unpadded.
    assert rod_babble.batch_sizes(400, 4096, on_accelerator=True, host_call=64) == [64] * 6 + [16]
    assert rod_babble.batch_sizes(53, 32, host_call=64) == [32, 21]


@pytest.mark.parametrize("on_accelerator", [True, False])
def test_chunked_and_padded_calls_give_the_same_poses(monkeypatch, on_accelerator):
    """Calls padded to one size (GPU) or cut in chunks (CPU) give the poses of one call, and
    report each call's trajectories to the progress bar."""
    monkeypatch.setenv("SOFTARM_THREADS", "1")  # CPU chunks of 2
    rod = mjx_arm.load_rod("source")
    programs = np.random.default_rng(0).uniform(0, 3.5, (3, 5, 3))
    done = []
    poses = rod_babble.simulate_rod(
        rod, programs, chunk=2, progress=done.append, on_accelerator=on_accelerator
    )
    assert done == [2, 1]
    np.testing.assert_allclose(poses, rod.rollout(programs), rtol=0, atol=1e-12)


def test_the_memory_estimate_lets_the_long_rod_set_through():
    long_dc = babble.BabbleConfig(
        n_train=400, duration_s=120.0, hold_min_s=1.0, hold_max_s=40.0,
        domains=("constrained",), backend="rod",
    )  # fmt: skip
    need = babble.memory_estimate_bytes(long_dc)
    # 403 x 1,200 periods x (3 + 6) float32 kept, plus one call of 403 float64 trajectories.
    assert 17e6 < need < 200e6
    assert babble.check_memory(long_dc, available=2_000_000_000) == need


def test_rod_refuses_an_mjcf_and_distributed_runs(tmp_path, capsys):
    out = str(tmp_path / "o")
    base = ["--backend", "rod", "--n", "1", "--n-val", "0", "--duration", "1", "--out", out]
    for extra, named in (
        (["--model", "models/softarm.xml"], "--model"),
        (["--distributed", "--coordinator", "h:1"], "--distributed"),
    ):
        with pytest.raises(SystemExit) as exc:
            babble_cli.parse_args([*base, *extra])
        assert exc.value.code == 2
        assert named in capsys.readouterr().err.split("error: ", 1)[1]
    config = babble.BabbleConfig(n_train=1, n_val=0, duration_s=1.0, backend="rod")
    with pytest.raises(ValueError, match="MJCF"):
        babble.babble(config, xml="<mujoco/>", progress=False)
    assert not (tmp_path / "o").exists()
