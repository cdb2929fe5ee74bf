"""CCGAN-GP in the reference rod end to end: rod babbling (`mjx_arm.babble --backend rod`), k
chosen in the rod (`--k-choice-simulator rod`), translator files labelled with the rod's model
hash; and the refusals of every mix of the rod's data, the chain's and their simulators.

Tiny settings (1 s programs, 1 seed, 2 epochs, 4-wide networks) on the CPU.
"""

import mjx_arm  # noqa: I001  (before jax: it sets an XLA CPU flag)

import dataclasses

import numpy as np
import pytest

from ccgan import checkpoint, distill
from ccgan import config as config_lib
from ccgan import data as data_lib
from ccgan import train as train_lib
from ccgan.sim_choice import SimulatorChoice, simulator_of
from ccgan.translator import is_rod_trained, load_translator, translator_labels
from mjx_arm import babble, dataset
from mjx_arm.programs import random_held_programs, shape_like_programs
from tracking import held, metrics
from tracking.config import ConfigError

TINY = ["--epochs", "2", "--batch-size", "2", "--window-length", "5", "--n-val", "2"]
TINY += ["--forward-epochs", "1", "--forward-hidden", "4", "--forward-fc", "4"]
TINY += ["--gen-hidden", "4", "--gen-fc", "4", "--gen-unroll", "1", "--feedback-unroll", "1"]
TINY += ["--critic-features", "4", "4", "4", "4", "4", "--no-progress"]
ROD_K = ["--k-choice", "simulator", "--k-choice-simulator", "rod", "--hold-factors", "1", "2"]
ROD_K += ["--stretch-every", "1", "--k-choice-seconds", "1"]


@pytest.fixture(scope="module")
def rod_data(tmp_path_factory):
    """Rod babbling of 2 + 2 programs of 1.5 s in both domains: {"s": [train, val], "c": ...}
    (as many held out as trained on: one batch shape, one rod compile per domain)."""
    out = tmp_path_factory.mktemp("rod") / "babble"
    config = babble.BabbleConfig(n_train=2, n_val=2, duration_s=1.5, backend="rod")
    babble.run(config, out, progress=False)
    return {
        key: [str(out / f"{domain}_{split}.npz") for split in ("train", "val")]
        for key, domain in (("s", "source"), ("c", "constrained"))
    }


@pytest.fixture(scope="module")
def chain_files(tmp_path_factory):
    """Synthetic chain files (the committed MJCF's model hash; no simulation), 15 steps."""
    folder = tmp_path_factory.mktemp("chain")
    model_hash = mjx_arm.load().model_hash
    rng = np.random.default_rng(0)
    files = {}
    for key, domain in (("s", "source"), ("c", "constrained")):
        pressures = random_held_programs(rng, 3, 15).astype(np.float32)
        poses = 0.1 + np.cumsum(rng.normal(scale=1e-3, size=(3, 15, 6)), axis=1)
        poses = poses.astype(np.float32)
        low, high = poses.reshape(-1, 6).min(0), poses.reshape(-1, 6).max(0)
        path = folder / f"{domain}.npz"
        dataset.save_dataset(
            path, dataset.Dataset(pressures, poses, low, high, domain, {}, model_hash, seed=1)
        )
        files[key] = [str(path)]
    return files


def usage_error(argv, capsys) -> str:
    with pytest.raises(SystemExit) as exc:
        train_lib.main(argv)
    assert exc.value.code == 2
    return capsys.readouterr().err.split("error: ", 1)[1]


@pytest.fixture(scope="module")
def rod_run(rod_data, tmp_path_factory):
    """The workdir of a tiny `python -m ccgan.train` on the rod's data, k chosen in the rod."""
    workdir = tmp_path_factory.mktemp("train") / "run"
    argv = ["--source", *rod_data["s"], "--constrained", *rod_data["c"], *TINY, *ROD_K]
    train_lib.main([*argv, "--workdir", str(workdir)])
    return workdir


@pytest.mark.slow  # a whole ccgan.train run on this CPU: 50-170 s (docs/testing.md)
def test_training_on_rod_data_chooses_k_in_the_rod_and_labels_the_translator(rod_run):
    rod, workdir = mjx_arm.load_rod("constrained"), rod_run
    rows = train_lib.read_rows(workdir / "k_choices.csv")
    # Scored before training, after epoch 1 (--stretch-every 1) and after the last (2).
    assert [r["epoch"] for r in rows] == [0, 1, 2]
    for r in rows:
        errors = [r["error_cm_k1"], r["error_cm_k2"]]
        assert all(np.isfinite(errors)) and min(errors) > 0
        assert r["k"] == (1, 2)[int(np.argmin(errors))]
    _, meta = checkpoint.load(workdir / "translator_seed0.ckpt")
    labels = translator_labels(meta)
    assert labels["model_hash"] == rod.model_hash and is_rod_trained(labels)
    assert (labels["source_domain"], labels["target_domain"]) == ("source", "constrained")
    assert meta["config"]["k_choice_simulator"] == "rod"
    # keep_best: the file's k is the k of the best trained scoring (epoch 1 or 2).
    best = min(rows[1:], key=lambda r: r[f"error_cm_k{int(r['k'])}"])
    translator = load_translator(workdir / "translator.ckpt", model_hash=rod.model_hash)
    assert translator.k == int(best["k"])
    with pytest.raises(checkpoint.CheckpointError, match="model_hash"):
        load_translator(workdir / "translator.ckpt", model_hash=mjx_arm.load().model_hash)


def test_the_rod_judge_scores_by_hand_and_takes_shape_like_targets_from_the_rod(rod_data):
    d_s = data_lib.read_domain(rod_data["s"], "source")
    d_c = data_lib.read_domain(rod_data["c"], "constrained")
    assert simulator_of(d_s.model_hash) == "rod" == simulator_of(d_c.model_hash)
    data = data_lib.prepare(
        d_s.pressures_bar, d_s.poses, d_c.pressures_bar, d_c.poses, 5, 2,
        bounds=data_lib.union_bounds(d_s.bounds, d_c.bounds),
    )  # fmt: skip
    config = config_lib.TrainConfig(
        k_choice_simulator="rod", hold_factors=(1, 2), k_choice_seconds=1.0, n_val=2,
        gen_hidden=4, gen_fc=4,
    )  # fmt: skip
    rod_c = mjx_arm.load_rod("constrained")
    judge = SimulatorChoice(rod_c, data, config)
    assert judge.backend == "rod" and judge.n_steps == 10
    commands = np.random.default_rng(1).uniform(0.2, 3.0, (1, 2, 10, 3))  # [S, n_val, T, 3]
    errors = judge.errors_of_commands(commands)
    for i, k in enumerate((1, 2)):
        poses = held.every_kth(rod_c.rollout(held.stretch(commands[0], k)), k)
        want = metrics.position_error_cm(poses, judge.target).mean(-1).mean(-1)
        assert errors[0, i] == pytest.approx(want, rel=1e-9)
    # The held-out targets are the rod's D_s poses (stored as float32).
    np.testing.assert_allclose(judge.target, d_s.poses[-2:, :10], atol=1e-6)

    shape_like = dataclasses.replace(config, k_choice_programs="shape_like", k_choice_n_programs=1)
    rod_s = mjx_arm.load_rod("source")
    judge = SimulatorChoice(rod_c, data, shape_like, source_arm=rod_s)
    program = shape_like_programs(1, 1.0, seed=0, split="k_choice", full_scale=True)
    np.testing.assert_allclose(judge.target[0], rod_s.rollout(program[0].astype(float)), atol=1e-6)
    with pytest.raises(ValueError, match="source_arm"):
        SimulatorChoice(rod_c, data, shape_like)
    # The chain's arms are refused for a rod choice, and the rod for a chain one.
    with pytest.raises(ValueError, match="k_choice_simulator is 'rod'"):
        SimulatorChoice(mjx_arm.load(domain="constrained"), data, config)
    with pytest.raises(ValueError, match="k_choice_simulator is 'chain'"):
        SimulatorChoice(rod_c, data, dataclasses.replace(config, k_choice_simulator="chain"))
    with pytest.raises(ValueError, match="source_arm"):
        SimulatorChoice(rod_c, data, shape_like, source_arm=mjx_arm.load(domain="source"))


def test_simulator_mixes_are_refused_before_any_work(rod_data, chain_files, tmp_path, capsys):
    workdir = tmp_path / "run"
    out = ["--workdir", str(workdir), *TINY]
    rod = ["--source", *rod_data["s"], "--constrained", *rod_data["c"]]
    chain = ["--source", *chain_files["s"], "--constrained", *chain_files["c"]]
    # Rod data, k chosen in the chain (the default simulator).
    err = usage_error([*rod, *out, "--k-choice", "simulator"], capsys)
    assert "--k-choice-simulator chain" in err and "reference rod" in err
    assert "--k-choice-simulator rod" in err
    # Chain data, k chosen in the rod.
    err = usage_error([*chain, *out, *ROD_K], capsys)
    assert "--k-choice-simulator rod" in err and "the chain" in err
    # One slot's rod data beside the other's chain data.
    mixed = ["--source", *rod_data["s"], "--constrained", *chain_files["c"]]
    err = usage_error([*mixed, *out, *ROD_K], capsys)
    assert "reference rod" in err and "chain" in err and "constrained.npz" in err
    # An MJCF named for rod data.
    err = usage_error([*rod, *out, *ROD_K, "--model", "models/softarm.xml"], capsys)
    assert err.startswith("--model") and "reference rod" in err
    # F_c's own data from the chain beside the rod's CCGAN data.
    err = usage_error([*rod, *out, *ROD_K, "--forward-data", *chain_files["c"]], capsys)
    assert "--forward-data" in err and "reference rod" in err and "chain" in err
    # The rod has no planning copy.
    err = usage_error([*rod, *out, *ROD_K, "--k-choice-substeps", "5"], capsys)
    assert "--k-choice-substeps" in err
    err = usage_error([*rod, *out, *ROD_K[:3], "pyelastica"], capsys)
    assert "--k-choice-simulator" in err
    assert not workdir.exists()


@pytest.mark.slow  # a whole ccgan.train run on this CPU: 50-170 s (docs/testing.md)
def test_the_chains_stages_refuse_a_rod_trained_translator(rod_run, tmp_path, capsys):
    """ccgan.distill simulates the chain: a rod-trained translator is refused, saying why."""
    out = tmp_path / "out"
    argv = ["--translators", str(rod_run / "translator.ckpt"), "--out", str(out)]
    with pytest.raises(SystemExit) as exc:
        distill.main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.split("error: ", 1)[1]
    assert "reference rod's data" in err and mjx_arm.load_rod().model_hash in err
    assert not out.exists()


def test_the_chain_default_is_left_out_of_stored_configs():
    """Every stored run predates k_choice_simulator: "chain" is not written, so they resume."""
    chain = config_lib.TrainConfig()
    assert "k_choice_simulator" not in chain.to_dict()
    assert config_lib.TrainConfig.from_dict(chain.to_dict()) == chain
    rod = config_lib.TrainConfig(k_choice_simulator="rod")
    assert rod.to_dict()["k_choice_simulator"] == "rod"
    assert config_lib.TrainConfig.from_dict(rod.to_dict()) == rod
    with pytest.raises(ConfigError, match="k_choice_simulator"):
        config_lib.TrainConfig(k_choice_simulator="mjx")
