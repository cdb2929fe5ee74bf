"""Tests of `ccgan.tune`: a tiny Optuna study through the CLI, its report, and its resumption."""

import json
import math

import numpy as np
import optuna
import pytest

import mjx_arm  # noqa: F401  (sets the XLA CPU flag before JAX creates its backend)
from ccgan import tune
from mjx_arm.dataset import Dataset, save_dataset
from mjx_arm.programs import random_held_programs

TINY_FLAGS = [
    "--epochs", "2", "--batch-size", "4", "--n-val", "1", "--hold-factors", "1", "2",
    "--stretch-every", "2", "--gen-hidden", "8", "--gen-fc", "16",
    "--critic-features", "8", "8", "8", "8", "8", "--space-window-lengths", "5",
    "--forward-epochs", "3", "--forward-batch-size", "6", "--forward-hidden", "16",
    "--forward-fc", "16", "--gen-unroll", "1", "--feedback-unroll", "1",
]  # fmt: skip


def _write_domain(path, rng, n, gain, domain):
    """Synthetic babbling: held random pressures, poses a first-order lag of them (6 dims),
    written as an `mjx_arm.dataset` file of `domain` (both domains: one made-up arm)."""
    pressures = random_held_programs(rng, n, 20)
    poses = np.zeros((n, 20, 6))
    pose = np.zeros((n, 6))
    for t in range(20):
        target = gain * np.concatenate([pressures[:, t], -pressures[:, t]], -1) / 3.5
        pose = pose + 0.5 * (target - pose)
        poses[:, t] = pose
    low, high = np.full(6, -gain), np.full(6, gain)
    arrays = [np.asarray(a, np.float32) for a in (pressures, poses, low, high)]
    save_dataset(path, Dataset(*arrays, domain, {}, "tinyarm", seed=0, split="train"))


def test_tiny_study_writes_report_and_resumes(tmp_path):
    rng = np.random.default_rng(0)
    _write_domain(tmp_path / "s.npz", rng, 5, 0.10, "source")
    _write_domain(tmp_path / "c.npz", rng, 4, 0.07, "constrained")  # unpaired: other count, gain
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
    ],
)
def test_bad_options_stop_before_any_trial(tmp_path, flags, named, capsys):
    rng = np.random.default_rng(0)
    _write_domain(tmp_path / "s.npz", rng, 5, 0.10, "source")
    _write_domain(tmp_path / "c.npz", rng, 4, 0.07, "constrained")
    (tmp_path / "FILE").write_text("")
    db = tmp_path / "study" / "tune.db"
    argv = [
        "--source", str(tmp_path / "s.npz"), "--constrained", str(tmp_path / "c.npz"),
        "--storage", str(db), "--report-dir", str(tmp_path / "report"), *TINY_FLAGS,
        "--n-trials", "1",
    ]  # fmt: skip
    flags = [str(tmp_path / f) if f == "FILE" else f for f in flags]
    with pytest.raises(SystemExit) as exc:
        tune.main([*argv, *flags])
    assert exc.value.code == 2 and named in capsys.readouterr().err.split("error: ", 1)[1]
    assert not db.parent.exists() and not (tmp_path / "report").exists()
