"""Tests of `ccgan.tune`: a tiny Optuna study through the CLI, its report, and its resumption."""

import json
import math

import numpy as np
import optuna
import pytest

import mjx_arm
from ccgan import tune
from mjx_arm.dataset import Dataset, save_dataset, workspace_bounds
from mjx_arm.programs import random_held_programs

TINY_FLAGS = [
    "--epochs", "2", "--stretch-every", "1", "--batch-size", "4", "--n-val", "1",
    "--hold-factors", "1", "2", "--k-choice-seconds", "1", "--gen-hidden", "8", "--gen-fc", "16",
    "--critic-features", "8", "8", "8", "8", "8", "--space-window-lengths", "5",
    "--space-critic-steps", "1", "--space-gen-residual", "false", "true",
    "--forward-epochs", "3", "--forward-batch-size", "6", "--forward-hidden", "16",
    "--forward-fc", "16", "--gen-unroll", "1", "--feedback-unroll", "1", "--no-progress",
]  # fmt: skip


@pytest.fixture(scope="module")
def small_arm_files(tmp_path_factory, small_xml):
    """Babbling of the 3-segment arm in both domains as dataset files, and its MJCF path."""
    folder = tmp_path_factory.mktemp("tune_data")
    (folder / "small.xml").write_text(small_xml)
    rng = np.random.default_rng(0)
    for domain, n in (("source", 5), ("constrained", 4)):  # unpaired: other counts
        arm = mjx_arm.load(folder / "small.xml", domain=domain)
        pressures = random_held_programs(rng, n, 20)
        poses = arm.rollout(pressures, backend="c")
        low, high = workspace_bounds(poses)
        arrays = [np.asarray(a, np.float32) for a in (pressures, poses, low, high)]
        ds = Dataset(*arrays, domain, {}, arm.model_hash, seed=0, split="train")
        save_dataset(folder / f"{domain}.npz", ds)
    return folder


def _argv(folder, tmp_path, db):
    return [
        "--source", str(folder / "source.npz"), "--constrained", str(folder / "constrained.npz"),
        "--model", str(folder / "small.xml"), "--storage", str(db), "--study-name", "tiny",
        "--report-dir", str(tmp_path / "report"), *TINY_FLAGS,
    ]  # fmt: skip


@pytest.mark.slow
def test_tiny_study_in_batches_scores_in_the_simulator_and_resumes(small_arm_files, tmp_path):
    db = tmp_path / "study" / "tune.db"
    argv = _argv(small_arm_files, tmp_path, db)

    # A batch of three trials: one structure, numbers sampled by TPE.
    tune.main([*argv, "--n-trials", "3", "--trials-per-batch", "3"])
    assert (db.parent / "tune_tiny_cache" / "forward_c_L5.ckpt").exists()
    report = json.loads((tmp_path / "report" / "tune.json").read_text())
    assert (tmp_path / "report" / "tune.md").exists()
    assert (tmp_path / "report" / "tune_history.png").stat().st_size > 0
    first = report["trials"]
    assert len(first) == 3 and set(t["state"] for t in first) <= {"COMPLETE", "PRUNED"}
    assert set(first[0]["params"]) == set(tune.TUNED)
    structures = tune.SearchSpace(window_lengths=(5,), critic_steps=(1,)).structures()
    for t in first:
        assert {n: t["params"][n] for n in tune.STRUCTURAL} == structures[t["batch"]]
        # The value is the simulator error at the trial's k, the lowest of its errors per k.
        errors = t["errors_cm"]
        assert t["k"] in (1, 2) and math.isfinite(t["stretch_only_cm"])
        if t["state"] == "COMPLETE":
            assert t["value_cm"] == pytest.approx(min(errors.values()))
            assert t["value_cm"] == pytest.approx(errors[str(t["k"])])
    assert [t["batch"] for t in first] == [0, 0, 0]
    done = [t["value_cm"] for t in first if t["value_cm"] is not None]
    assert report["best"]["value_cm"] == min(done)

    # The same command with more trials continues the stored study with the next structure.
    tune.main([*argv, "--n-trials", "1", "--trials-per-batch", "2"])
    study = optuna.load_study(study_name="tiny", storage=f"sqlite:///{db}")
    assert len(study.trials) == 4
    for t, old in zip(study.trials[:3], first, strict=True):
        assert t.params == old["params"] and t.value == old["value_cm"]
    assert study.trials[3].user_attrs["batch"] == 1
    assert study.trials[3].params["gen_residual"] is structures[1]["gen_residual"] is True
    assert len(json.loads((tmp_path / "report" / "tune.json").read_text())["trials"]) == 4
    # The report rewritten from the storage alone, with its table by structure.
    (tmp_path / "report" / "tune.md").unlink()
    tune.main([*argv, "--report-only"])
    text = (tmp_path / "report" / "tune.md").read_text()
    assert "| window_length | critic_steps | gen_residual | trials | pruned |" in text
    assert "| 5 | 1 | False | 3 |" in text and "| 5 | 1 | True | 1 |" in text


@pytest.mark.slow  # CI's slowest test (two vmapped trainings compile; docs/testing.md)
def test_batch_equals_one_setting_at_a_time_and_refuses_mixed_structures(small_arm_files):
    """Members of a vmapped batch do not interact: reordered, each gives the same result."""
    import dataclasses

    from ccgan import data as data_lib
    from ccgan import forward as forward_lib
    from ccgan.batch import BatchTrainer
    from ccgan.config import TrainConfig
    from ccgan.sim_choice import SimulatorChoice
    from mjx_arm.dataset import load_dataset

    d_s, d_c = (load_dataset(small_arm_files / f"{d}.npz") for d in ("source", "constrained"))
    data = data_lib.prepare(
        d_s.pressures_bar, d_s.poses, d_c.pressures_bar, d_c.poses, window_length=5, n_val=1
    )
    fconf = forward_lib.ForwardConfig(epochs=2, batch_size=6, hidden=8, fc=8)
    fparams, _, _ = forward_lib.train_forward(fconf, data.constrained, data.bounds)
    base = TrainConfig(
        epochs=2, stretch_every=1, batch_size=4, window_length=5, n_val=1, hold_factors=(1, 2),
        k_choice_seconds=1.0, gen_hidden=4, gen_fc=8, critic_features=(4,) * 5,
    )  # fmt: skip
    arm_c = mjx_arm.load(small_arm_files / "small.xml", domain="constrained")
    trainer = BatchTrainer(data, fparams, SimulatorChoice(arm_c, data, base), fconf.model)
    configs = [base, dataclasses.replace(base, lambda_cycle=1.0, lr_generator=3e-4)]
    both = trainer.train(configs, seeds=(0, 1))
    assert both.error_cm.shape == (2, 2) and np.isfinite(both.error_cm).all()
    # One history entry per scoring (epochs 1 and 2); the last is the final score.
    assert [h["epoch"] for h in both.history] == [1, 2]
    np.testing.assert_array_equal(both.history[-1]["error_cm"], both.error_cm)
    np.testing.assert_array_equal(both.history[0]["index"], [0, 1])
    swapped = trainer.train(configs[::-1], seeds=(1, 0))
    np.testing.assert_allclose(swapped.error_cm[::-1, ::-1], both.error_cm, rtol=1e-4)
    np.testing.assert_array_equal(swapped.k[::-1, ::-1], both.k)
    # Two settings, two results: the numbers reach the training.
    assert not np.allclose(both.errors_cm[0], both.errors_cm[1])
    with pytest.raises(ValueError, match="differ only in"):
        trainer.train([base, dataclasses.replace(base, critic_steps=2)])


@pytest.mark.parametrize(
    "flags, named",
    [
        (["--n-trials", "0"], "--n-trials"),
        (["--timeout-s", "0"], "--timeout-s"),
        (["--report-dir", "FILE"], "--report-dir"),
        (["--space-window-lengths", "1", "5"], "--space-window-lengths"),
        (["--space-lr-critic", "1e-3", "1e-5"], "--space-lr-critic"),
        (["--forward-batch-size", "0"], "--forward-batch-size"),
        (["--batch-size", "0"], "--batch-size"),
        (["--trials-per-batch", "0"], "--trials-per-batch"),
        (["--space-critic-steps", "0"], "--space-critic-steps"),
        (["--model", "models/softarm.xml"], "hash"),
        (["--k-choice-simulator", "rod"], "--k-choice-simulator rod"),
    ],
)
def test_bad_options_stop_before_any_trial(small_arm_files, tmp_path, flags, named, capsys):
    (tmp_path / "FILE").write_text("")
    db = tmp_path / "study" / "tune.db"
    argv = [*_argv(small_arm_files, tmp_path, db), "--n-trials", "1"]
    flags = [str(tmp_path / f) if f == "FILE" else f for f in flags]
    with pytest.raises(SystemExit) as exc:
        tune.main([*argv, *flags])
    assert exc.value.code == 2 and named in capsys.readouterr().err.split("error: ", 1)[1]
    assert not db.parent.exists() and not (tmp_path / "report").exists()
