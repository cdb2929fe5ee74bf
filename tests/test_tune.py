"""Tests of `ccgan.tune`: a tiny Optuna study through the CLI, its report, and its resumption."""

import json
import math

import numpy as np
import optuna

import mjx_arm  # noqa: F401  (sets the XLA CPU flag before JAX creates its backend)
from ccgan import data as data_lib
from ccgan import tune

TINY_FLAGS = [
    "--epochs", "2", "--batch-size", "4", "--n-val", "1", "--stretch-choices", "1", "2",
    "--stretch-every", "2", "--gen-hidden", "8", "--gen-fc", "16",
    "--critic-features", "8", "8", "8", "8", "8", "--space-window-lengths", "5",
    "--forward-epochs", "3", "--forward-batch-size", "6", "--forward-hidden", "16",
    "--forward-fc", "16", "--gen-unroll", "1", "--feedback-unroll", "1",
]  # fmt: skip


def _write_domain(path, rng, n, gain):
    """Synthetic babbling: held random pressures, poses a first-order lag of them (6 dims)."""
    pressures = data_lib.random_held_programs(rng, n, 20)
    poses = np.zeros((n, 20, 6))
    pose = np.zeros((n, 6))
    for t in range(20):
        target = gain * np.concatenate([pressures[:, t], -pressures[:, t]], -1) / 3.5
        pose = pose + 0.5 * (target - pose)
        poses[:, t] = pose
    np.savez(path, pressures_bar=pressures, poses=poses)


def test_tiny_study_writes_report_and_resumes(tmp_path):
    rng = np.random.default_rng(0)
    _write_domain(tmp_path / "s.npz", rng, 5, 0.10)
    _write_domain(tmp_path / "c.npz", rng, 4, 0.07)  # unpaired: other count and gain
    db = tmp_path / "study" / "tune.db"
    argv = [
        "--source", str(tmp_path / "s.npz"), "--constrained", str(tmp_path / "c.npz"),
        "--storage", str(db), "--study-name", "tiny", "--report-dir", str(tmp_path / "report"),
        *TINY_FLAGS,
    ]  # fmt: skip

    tune.main([*argv, "--n-trials", "2"])
    assert db.exists()
    assert (db.parent / "tune_tiny_cache" / "forward_c_L5.ckpt").exists()
    report = json.loads((tmp_path / "report" / "tune.json").read_text())
    assert (tmp_path / "report" / "tune.md").exists()
    assert (tmp_path / "report" / "tune_history.png").stat().st_size > 0
    first = report["trials"]
    assert len(first) == 2 and all(t["state"] == "COMPLETE" for t in first)
    assert all(math.isfinite(t["value_cm"]) for t in first)
    assert set(first[0]["params"]) == set(tune.TUNED)
    assert report["best"]["value_cm"] == min(t["value_cm"] for t in first)

    # The same command with one more trial continues the stored study.
    tune.main([*argv, "--n-trials", "1"])
    study = optuna.load_study(study_name="tiny", storage=f"sqlite:///{db}")
    assert len(study.trials) == 3
    for t, old in zip(study.trials[:2], first, strict=True):
        assert t.params == old["params"] and t.value == old["value_cm"]
    assert math.isfinite(study.trials[2].value)
    # The resumed sampler does not replay the first trial's start-up point.
    assert study.trials[2].params != study.trials[0].params
    assert len(json.loads((tmp_path / "report" / "tune.json").read_text())["trials"]) == 3
