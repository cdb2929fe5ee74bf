"""Tests of ccgan.distill: G_c trained to imitate tracking.mpc's commands (CPU, tiny)."""

import dataclasses
import hashlib
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjx_arm
from ccgan import checkpoint, distill, load_translator
from ccgan.translator import METHODS, translator_path
from mjx_arm import constants
from mjx_arm.programs import shape_like_programs
from tracking.metrics import position_error_cm

# k = 5, not the committed translators' 15: a third of the simulation, and nothing here depends
# on k.
TINY = distill.DistillConfig(
    n_train=4, n_val=2, duration_s=1.0, epochs=4, batch_size=2, eval_every=2, learning_rate=3e-3,
    hold_factor=5,
)  # fmt: skip


def x_err_cm(arm_c, commands, k: int, target) -> float:
    """Mean X_err (cm) of commands [B, T, 3] (bar, one per source step) held k periods in
    MuJoCo C against targets [B, T, 6]."""
    held = arm_c.rollout(np.repeat(np.asarray(commands, np.float64), k, axis=1), backend="c")
    return float(position_error_cm(held[:, k - 1 :: k], target).mean())


@pytest.fixture(scope="module")
def arms(small_xml):
    return mjx_arm.load(xml=small_xml, domain="source"), mjx_arm.load(
        xml=small_xml, domain="constrained"
    )


def test_distill_imitates_the_teacher_and_caches_it(arms, tmp_path):
    arm_s, arm_c = arms
    shipped = load_translator()
    cache = tmp_path / "teacher.npz"
    logs = []
    reports = []

    def on_validation(best, hist):
        reports.append((hist["complete"], list(hist["best_epoch"]), best[0]))

    params, history = distill.distill(
        [shipped],
        arm_s,
        arm_c,
        TINY,
        cache=cache,
        progress=False,
        log=logs.append,
        on_validation=on_validation,
    )
    # The best iterates so far were reported after the validations at epochs 2 and 4; the last
    # report is the result.
    assert [r[0] for r in reports] == [False, False] and history["complete"]
    assert reports[-1][1] == history["best_epoch"]
    for got, want in zip(jax.tree.leaves(reports[-1][2]), jax.tree.leaves(params[0]), strict=True):
        np.testing.assert_array_equal(got, want)
    assert cache.exists() and not any("read from" in line for line in logs)
    # Imitation: the mean squared error to the teacher's commands falls.
    loss = np.asarray(history["train_loss"])
    assert loss.shape == (4, 1) and loss[-1, 0] < loss[0, 0]
    assert sorted(history["val"]) == [0, 2, 4]
    # The kept iterate is never worse than the start, and is the one the history names.
    assert history["best_val_x_err_cm"][0] <= history["val_x_err_cm_before"][0]
    best = history["val"][history["best_epoch"][0]]["score"][0]
    assert history["best_val_x_err_cm"][0] == best
    # The teacher tracks its held-out programs better than the untuned translator does.
    assert history["teacher_val_x_err_cm"]["whole"] < history["val"][0]["whole"][0]

    # The score, recomputed from the returned parameters in MuJoCo C.
    logs.clear()
    data = distill.teacher_data(TINY, arm_s, arm_c, TINY.hold_factor, cache, log=logs.append)
    assert all("read from" in line for line in logs) and len(logs) == 2
    np.testing.assert_array_equal(distill.held_out_programs(TINY).astype(np.float32), data["p_val"])
    # Stretch only on the same held-out programs: the D_s commands held k periods in D_c.
    k = TINY.hold_factor
    held = arm_c.rollout(np.repeat(data["p_val"], k, axis=1), backend="c")[:, k - 1 :: k]
    want = position_error_cm(held, data["x_val"]).mean()
    assert np.isclose(history["stretch_val_x_err_cm"]["whole"], want, rtol=1e-6)
    tuned = dataclasses.replace(shipped, g_c_params=params[0], k=TINY.hold_factor)
    x_val = data["x_val"].astype(np.float64)
    pairs = zip(data["p_val"], x_val, strict=True)
    cmds = np.stack([tuned.translate(p, x)[0][:: tuned.k] for p, x in pairs])
    whole = x_err_cm(arm_c, cmds, tuned.k, x_val)
    head = x_err_cm(arm_c, cmds[:, :20], tuned.k, x_val[:, :20])
    # One program at a time here, all at once in the validation: float32 G_c in two batch
    # layouts, a rounding apart, and nothing between G_c and the score amplifies it.
    np.testing.assert_allclose(0.5 * (whole + head), best, rtol=1e-4)

    # The cache grows: more programs plan only the new ones, which match a fresh plan.
    logs.clear()
    more = distill.teacher_data(
        dataclasses.replace(TINY, n_train=5, n_val=1),
        arm_s,
        arm_c,
        TINY.hold_factor,
        cache,
        logs.append,
    )
    assert "read from" in logs[0] and more["p_val"].shape[0] == 1
    assert logs[1].startswith("teacher (c): 1 new train programs of 1.0 s")
    np.testing.assert_array_equal(more["c_train"][:4], data["c_train"])
    fresh = distill.teacher_data(
        dataclasses.replace(TINY, n_train=5, n_val=1),
        arm_s,
        arm_c,
        TINY.hold_factor,
        None,
        logs.append,
    )
    np.testing.assert_allclose(fresh["c_train"][4], more["c_train"][4], atol=1e-6)
    # Full-amplitude programs follow each split's own programs.
    logs.clear()
    both = distill.teacher_data(
        dataclasses.replace(TINY, n_train=5, n_val=1, n_train_full=2, n_val_full=1),
        arm_s, arm_c, TINY.hold_factor, cache, logs.append,
    )  # fmt: skip
    assert both["p_train"].shape[0] == 7 and both["p_val"].shape[0] == 2
    np.testing.assert_array_equal(both["c_train"][:5], more["c_train"])
    full = shape_like_programs(2, 1.0, split="distill/train_full", full_scale=True)
    np.testing.assert_array_equal(both["p_train"][5:], full)
    assert len(both["teacher_val_x_err_cm"]) == 2
    # Other settings or a corrupt file: planned again, never mixed; the other settings' cache
    # is moved aside, not overwritten.
    logs.clear()
    other = dataclasses.replace(TINY, duration_s=0.5, n_val=1)
    again = distill.teacher_data(other, arm_s, arm_c, TINY.hold_factor, cache, log=logs.append)
    assert "other settings (duration_s: stored 1.0, this run 0.5)" in logs[0]
    assert again["p_val"].shape == (1, 5, 3)
    (aside,) = tmp_path.glob("teacher.constrained-*.npz")
    with np.load(aside) as f:
        np.testing.assert_array_equal(f["c_train"][:5], more["c_train"])
    cache.write_bytes(b"not an npz")
    logs.clear()
    distill.teacher_data(other, arm_s, arm_c, TINY.hold_factor, cache, log=logs.append)
    assert "not a readable teacher cache" in logs[0] and np.load(cache)["p_val"].shape[0] == 1


def test_distill_cli_writes_translators_with_their_history(tmp_path):
    source = translator_path()
    out = tmp_path / "run"
    args = ["--translators", str(source), "--out", str(out), "--n-train", "2", "--n-val", "1"]
    args += ["--duration-s", "0.5", "--epochs", "1", "--batch-size", "2", "--eval-every", "1"]
    distill.main(args)
    tuned = load_translator(out / "translator_seed0.ckpt")
    _, meta = checkpoint.load(out / "translator.ckpt")
    assert meta["finetune"]["method"] == "distill" and meta["finetune"]["seed"] == 0
    assert meta["finetune"]["complete"]
    # Started from the CCGAN-GP translator: labelled "distill", its start recorded.
    assert meta["method"] == "distill" and meta["started_from"]["method"] == "ccgan"
    assert meta["started_from"]["path"] == str(source)
    assert meta["started_from"]["sha256"] == checkpoint.payload_sha256(source)
    # By default the stage simulates the I-Support arm the shipped translators were trained on.
    arm = mjx_arm.load(constants.TRANSLATOR_MODEL_PATH)
    assert meta["finetune"]["model"] == str(constants.TRANSLATOR_MODEL_PATH)
    assert meta["finetune"]["model_hash"] == arm.model_hash
    assert (out / "teacher.npz").exists() and (out / "distill.json").exists()
    shipped = load_translator(source)
    assert tuned.k == shipped.k
    leaves = jax.tree.leaves(tuned.g_c_params), jax.tree.leaves(shipped.g_c_params)
    assert [x.shape for x in leaves[0]] == [x.shape for x in leaves[1]]


def test_distill_cli_sets_one_hold_factor_for_translators_that_disagree(tmp_path):
    """Seeds whose trainings chose different k: refused without --hold-factor; with it the
    teacher plans at that k and every file written holds its commands k periods."""
    source = translator_path()
    tree, meta = checkpoint.load(source)
    other = checkpoint.save(tmp_path / "other_k.ckpt", tree, meta | {"k": meta["k"] + 1})
    out = tmp_path / "run"
    args = ["--translators", str(source), str(other), "--out", str(out), "--n-train", "2"]
    args += ["--n-val", "1", "--duration-s", "0.5", "--epochs", "1", "--batch-size", "2"]
    args += ["--eval-every", "1"]
    with pytest.raises(SystemExit):
        distill.main(args)
    assert not (out / "translator.ckpt").exists()
    distill.main(args + ["--hold-factor", "3"])
    assert [load_translator(out / f"translator_seed{s}.ckpt").k for s in (0, 1)] == [3, 3]
    with np.load(out / "teacher.npz") as f:
        assert '"k": 3' in str(f["key"])


def test_teacher_cache_keeps_each_split_planned_before_a_stop(arms, tmp_path, monkeypatch):
    """A run stopped while planning the held-out split (a deadline's SIGTERM) keeps the training
    split's commands, and the rerun plans only the held-out split."""
    arm_s, arm_c = arms
    k = TINY.hold_factor
    config = dataclasses.replace(TINY, n_train=2, n_val=1, duration_s=0.5)
    cache = tmp_path / "teacher.npz"
    track = distill.mpc.track
    calls = []

    def stopped_on_second_split(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt("stopped")
        return track(*args, **kwargs)

    monkeypatch.setattr(distill.mpc, "track", stopped_on_second_split)
    with pytest.raises(KeyboardInterrupt):
        distill.teacher_data(config, arm_s, arm_c, k, cache, log=lambda _: None)
    with np.load(cache) as kept:
        assert kept["p_train"].shape[0] == 2 and "p_val" not in kept.files
    assert not [p for p in tmp_path.iterdir() if p.name != "teacher.npz"]  # no temporaries left
    monkeypatch.setattr(distill.mpc, "track", track)
    logs = []
    data = distill.teacher_data(config, arm_s, arm_c, k, cache, log=logs.append)
    assert "read from" in logs[0] and logs[1].startswith("teacher (c): 1 new val programs")
    assert data["p_train"].shape[0] == 2 and data["p_val"].shape[0] == 1


def test_mjx_teacher_plans_in_shards_as_the_c_teacher(arms, tmp_path):
    """The teacher on the accelerator (`tracking.mpc_mjx`), a shard of programs per call: its
    cache has its own key, and its commands track as well as the C teacher's.

    Why not compare the commands of a shard of 2 with those planned one by one: float32 MJX in
    another batch layout sums in another order (XLA), and the planner amplifies the rounding
    (0.0225 bar apart on some x86-64 CPUs). So the test compares what does not depend on the
    layout: the shards' logs, the programs and targets each split receives (bit for bit), the
    commands of programs planned in the same layout (a shard of 1 in both runs: bit for bit),
    and, for the shard of 2, how well each program's commands track its own targets (within
    10% of the same program planned alone; a shuffled or misassigned shard tracks another
    program's targets, several times worse, which the test checks too)."""
    arm_s, arm_c = arms
    k = TINY.hold_factor
    one_step = dataclasses.replace(TINY, n_train=2, n_val=1, duration_s=0.5, iterations=1)
    on_mjx = dataclasses.replace(one_step, teacher_backend="mjx", teacher_shard=1)
    cache = tmp_path / "teacher.npz"
    logs = []
    data = distill.teacher_data(on_mjx, arm_s, arm_c, k, cache, log=logs.append)
    assert [line.split(" s (")[0] + " s" for line in logs] == [
        "teacher (mjx): 1 new train programs of 0.5 s",
        "teacher (mjx): 1 new train programs of 0.5 s",
        "teacher (mjx): 1 new val programs of 0.5 s",
    ]
    assert logs[1].endswith("2 of 3") and data["c_train"].shape == (2, 5, 3)
    # A shard of 2 spans the splits: the training split's second program and the held-out one.
    cache_2 = tmp_path / "teacher_2.npz"
    first = dataclasses.replace(on_mjx, n_train=1, n_val=0, n_val_full=1, batch_size=1)
    distill.teacher_data(first, arm_s, arm_c, k, cache_2, log=len)
    logs.clear()
    twos = dataclasses.replace(first, n_train=2, n_val=1, teacher_shard=2)
    again = distill.teacher_data(twos, arm_s, arm_c, k, cache_2, log=logs.append)
    assert logs[-1].startswith("teacher (mjx): 1 new train programs + 1 new val programs of 0.5 s")
    assert logs[-1].endswith("2 of 2")
    for part in ("p", "x"):  # each split got its own programs and targets, in order
        np.testing.assert_array_equal(again[f"{part}_train"], data[f"{part}_train"])
        np.testing.assert_array_equal(again[f"{part}_val"][:1], data[f"{part}_val"])
    # The first training program was a shard of 1 in both runs: the same layout, the same plan.
    np.testing.assert_array_equal(again["c_train"][0], data["c_train"][0])
    # The shard of 2 against the same programs planned one by one: each tracks its own targets.
    targets = np.stack([data["x_train"][1], data["x_val"][0]])
    in_shard = np.stack([again["c_train"][1], again["c_val"][0]])
    alone = np.stack([data["c_train"][1], data["c_val"][0]])

    def each(commands) -> list[float]:
        return [x_err_cm(arm_c, commands[i : i + 1], k, targets[i : i + 1]) for i in (0, 1)]

    wanted = each(alone)
    np.testing.assert_allclose(each(in_shard), wanted, rtol=0.1)
    assert min(each(in_shard[::-1])) > 1.5 * max(wanted)  # what a misassigned shard would give
    with np.load(cache) as f:
        assert '"teacher_backend": "mjx"' in str(f["key"])
        assert '"mjx_matmul_precision": "highest"' in str(f["key"])
    on_c = distill.teacher_data(one_step, arm_s, arm_c, k, tmp_path / "c.npz", log=logs.append)
    np.testing.assert_array_equal(on_c["p_train"], data["p_train"])
    np.testing.assert_allclose(
        data["teacher_val_x_err_cm"], on_c["teacher_val_x_err_cm"], rtol=0.01
    )


def test_distill_config_refuses_a_teacher_it_cannot_run():
    with pytest.raises(distill.ConfigError, match="teacher_backend"):
        dataclasses.replace(TINY, teacher_backend="gpu")
    with pytest.raises(distill.ConfigError, match="horizon_steps"):
        dataclasses.replace(TINY, teacher_backend="mjx", horizon_steps=2)


def test_distill_cli_teacher_only_plans_and_stops(tmp_path):
    out = tmp_path / "run"
    args = ["--translators", str(translator_path()), "--out", str(out), "--n-train", "2"]
    args += ["--n-val", "1", "--duration-s", "0.3", "--batch-size", "2", "--teacher-only"]
    distill.main(args)
    assert (out / "teacher.npz").exists() and not (out / "translator.ckpt").exists()
    with np.load(out / "teacher.npz") as f:
        assert f["c_train"].shape == (2, 3, 3) and f["c_val"].shape == (1, 3, 3)


def test_a_teacher_planned_without_translators_teaches_another_run(tmp_path, monkeypatch, capsys):
    """A chain plans its teacher while the translators train: --teacher-only with --hold-factor
    and no --translators, then the distillation starts from that cache (--teacher-from) and
    plans nothing; a cache of other settings, or a run without translators, is refused."""
    k = TINY.hold_factor
    common = ["--n-train", "2", "--n-val", "1", "--duration-s", "0.3", "--batch-size", "2"]
    common += ["--hold-factor", str(k)]
    with pytest.raises(SystemExit) as no_k:
        distill.main(["--out", str(tmp_path / "t0"), "--teacher-only"] + common[:-2])
    assert no_k.value.code == 2 and "needs --hold-factor" in capsys.readouterr().err
    planned = tmp_path / "teacher"
    distill.main(["--out", str(planned), "--teacher-only"] + common)
    with np.load(planned / "teacher.npz") as f:
        assert f["c_train"].shape == (2, 3, 3)
        want = f["c_train"].copy()
    with pytest.raises(SystemExit) as no_translators:
        distill.main(["--out", str(tmp_path / "t1")] + common)
    assert no_translators.value.code == 2 and "--translators is required" in capsys.readouterr().err

    def no_planning(*args, **kwargs):
        raise AssertionError("the teacher was planned again")

    monkeypatch.setattr(distill.mpc, "track", no_planning)
    out = tmp_path / "run"
    args = ["--translators", str(translator_path()), "--out", str(out), "--epochs", "1"]
    args += ["--eval-every", "1", "--teacher-from", str(planned / "teacher.npz")] + common
    distill.main(args)
    assert "teacher: started from" in capsys.readouterr().out
    assert load_translator(out / "translator.ckpt").k == k
    with np.load(out / "teacher.npz") as f:
        np.testing.assert_array_equal(f["c_train"], want)
    other = [a if a != "0.3" else "0.4" for a in args]
    with pytest.raises(SystemExit) as refused:
        distill.main([a if a != str(out) else str(tmp_path / "other") for a in other])
    assert refused.value.code == 2 and "planned with other settings" in capsys.readouterr().err
    assert not (tmp_path / "other" / "teacher.npz").exists()


def test_distill_cli_stopped_teacher_keeps_its_progress_and_says_rerun(tmp_path, monkeypatch):
    """The MJX teacher past --max-wall-s stops part-way through a shard, into
    teacher_partial.npz beside the cache, and the CLI exits 143 (rerun to go on)."""
    seen = []

    def stopped(arm_c, targets, k, programs, cfg, progress, resume, should_stop):
        seen.append((resume, should_stop()))
        raise distill.mpc_mjx.TrackingStopped(3, targets.shape[1], resume)

    monkeypatch.setattr(distill.mpc_mjx, "track", stopped)
    out = tmp_path / "run"
    args = ["--translators", str(translator_path()), "--out", str(out), "--n-train", "2"]
    args += ["--n-val", "1", "--duration-s", "0.5", "--batch-size", "2", "--teacher-only"]
    args += ["--teacher-backend", "mjx", "--iterations", "1", "--max-wall-s", "1e-6"]
    with pytest.raises(SystemExit) as stop:
        distill.main(args)
    assert stop.value.code == 143
    assert seen == [(out / "teacher_partial.npz", True)]


def test_final_lr_factor_decays_the_step_size_over_the_run():
    """With final_lr_factor 0 the step size reaches 0 after the run's last step: a one-epoch,
    one-batch run's first step moves G_c, a second step leaves it as it was."""
    translator = load_translator()
    rng = np.random.default_rng(0)
    data = distill.ImitationData(
        s_train=jnp.asarray(rng.uniform(size=(4, 6, 9)), jnp.float32),
        c_train=jnp.asarray(rng.uniform(size=(4, 6, 3)), jnp.float32),
        s_val=None, x_val=None, p_val=None, c_val=None, teacher_val_x_err_cm=None, window=2,
    )  # fmt: skip
    config = dataclasses.replace(TINY, epochs=1, batch_size=4, final_lr_factor=0.0)
    step, start, opt_state = distill.init_imitation([translator], config, data)
    first, opt_state, _ = step(start, opt_state, data.s_train, data.c_train)
    second, _, _ = step(first, opt_state, data.s_train, data.c_train)

    def moved(a, b) -> float:
        return max(
            float(jnp.abs(x - y).max())
            for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True)
        )

    assert moved(start, first) > 0.0 and moved(first, second) == 0.0
    with pytest.raises(distill.ConfigError, match="final_lr_factor"):
        dataclasses.replace(TINY, final_lr_factor=-0.5)


def test_teacher_data_adds_the_babbling_family(arms, tmp_path):
    """Babbling programs (their own stream) follow each split's shape-like programs, and count
    towards the batch-size check."""
    from mjx_arm.babble import BabbleConfig
    from mjx_arm.programs import babble_programs

    arm_s, arm_c = arms
    config = dataclasses.replace(
        TINY, n_train=1, n_train_babble=1, n_val=0, n_val_babble=1, duration_s=0.5, batch_size=2
    )
    logs = []
    data = distill.teacher_data(config, arm_s, arm_c, 2, tmp_path / "t.npz", log=logs.append)
    assert data["p_train"].shape == (2, 5, 3) and data["p_val"].shape == (1, 5, 3)
    spec = BabbleConfig(seed=0, duration_s=0.5)
    np.testing.assert_array_equal(
        data["p_train"][1], babble_programs(spec, [0], domain="distill", split="train_babble")[0]
    )
    assert not np.array_equal(data["p_train"][1], data["p_val"][0])  # a stream per split
    assert data["c_train"].shape == (2, 5, 3) and np.isfinite(data["teacher_val_x_err_cm"]).all()
    with pytest.raises(distill.ConfigError, match="n_train_babble"):
        dataclasses.replace(config, batch_size=3)


def _resumes_to_the_whole_run(shipped, arms, config, cache, state, whole, whole_history):
    """Resumed from `state` after epoch 2 of 4, a run trains epochs 3-4 only, removes the state
    and ends where the unstopped run (`whole`, `whole_history`) ends, bit for bit."""
    arm_s, arm_c = arms
    logs = []
    resumed, history = distill.distill(
        [shipped], arm_s, arm_c, config, cache=cache, progress=False, log=logs.append,
        resume=state,
    )  # fmt: skip
    assert any("2 of 4 epochs done" in line for line in logs)
    assert history["complete"] and not state.exists()
    assert history["train_loss"] == whole_history["train_loss"]
    assert history["best_epoch"] == whole_history["best_epoch"]
    for got, want in zip(jax.tree.leaves(resumed[0]), jax.tree.leaves(whole[0]), strict=True):
        np.testing.assert_array_equal(got, want)


def test_a_stopped_distillation_goes_on_from_its_next_epoch(arms, tmp_path):
    """Stopped after epoch 2 of 4 (SIGTERM's event, set at epoch 1's validation: training stops
    after the next epoch), a run keeps its training state; the same call then trains epochs 3-4
    only, and ends where an unstopped run ends, bit for bit. A state saved under other settings
    is not used."""
    import threading

    every = dataclasses.replace(TINY, eval_every=1)  # the same validations, stopped or not

    arm_s, arm_c = arms
    shipped = load_translator()
    cache, state = tmp_path / "teacher.npz", tmp_path / "training_state.npz"
    whole, whole_history = distill.distill(
        [shipped], arm_s, arm_c, every, cache=cache, progress=False, log=lambda _: None
    )
    stop = threading.Event()

    def stop_after_first_report(best, hist):
        stop.set()

    _, stopped = distill.distill(
        [shipped], arm_s, arm_c, every, cache=cache, progress=False, log=lambda _: None,
        on_validation=stop_after_first_report, stop=stop, resume=state,
    )  # fmt: skip
    assert not stopped["complete"] and len(stopped["train_loss"]) == 2 and state.exists()
    _resumes_to_the_whole_run(shipped, arms, every, cache, state, whole, whole_history)
    # Saved for 6 epochs, read by a run of 4: trained afresh, from epoch 1.
    stop.clear()
    six = dataclasses.replace(every, epochs=6)
    distill.distill(
        [shipped], arm_s, arm_c, six, cache=cache, progress=False, log=lambda _: None,
        on_validation=stop_after_first_report, stop=stop, resume=state,
    )  # fmt: skip
    logs = []
    _, afresh = distill.distill(
        [shipped], arm_s, arm_c, every, cache=cache, progress=False, log=logs.append,
        resume=state,
    )  # fmt: skip
    assert any("other settings" in line for line in logs) and len(afresh["train_loss"]) == 4


def test_a_killed_distillation_goes_on_from_its_last_validation(arms, tmp_path):
    """A run killed with no chance to save (a machine's time limit: SIGKILL, here an exception
    from the callback) still left the training state of its last validation, epoch 2 of 4; the
    same call then trains epochs 3-4 only and ends where an unkilled run ends, bit for bit."""

    class Killed(Exception):
        pass

    every = dataclasses.replace(TINY, eval_every=1)
    arm_s, arm_c = arms
    shipped = load_translator()
    cache, state = tmp_path / "teacher.npz", tmp_path / "training_state.npz"
    whole, whole_history = distill.distill(
        [shipped], arm_s, arm_c, every, cache=cache, progress=False, log=lambda _: None
    )
    reports = []

    def killed_at_second_report(best, hist):
        reports.append(len(hist["train_loss"]))
        if len(reports) == 2:
            raise Killed

    with pytest.raises(Killed):
        distill.distill(
            [shipped], arm_s, arm_c, every, cache=cache, progress=False, log=lambda _: None,
            on_validation=killed_at_second_report, resume=state,
        )  # fmt: skip
    assert reports == [1, 2] and state.exists()
    _resumes_to_the_whole_run(shipped, arms, every, cache, state, whole, whole_history)


def test_teacher_cache_key_records_the_domain_programs_and_planner(arms, small_xml):
    """The aged arm's commands are not the constrained arm's: the key names the domain (its name
    and values), besides k, the arm, each split's program family and every planner setting."""
    _, arm_c = arms
    arm_aged = mjx_arm.load(xml=small_xml, domain="aged")
    key = json.loads(distill.teacher_cache_key(TINY, 5, arm_c))
    assert key["k"] == 5 and key["model"] == arm_c.model_hash
    assert key["domain"]["name"] == "constrained" and key["domain"]["stiffness_scale"] == 1.0
    assert key["programs"] == {
        "train": "shape_like", "train_full": "shape_like_full", "train_babble": "babbling",
        "val": "shape_like", "val_full": "shape_like_full", "val_babble": "babbling",
    }  # fmt: skip
    assert key["planner"] == dataclasses.asdict(
        distill.mpc.MpcConfig(horizon_steps=1, iterations=2)
    )
    aged = json.loads(distill.teacher_cache_key(TINY, 5, arm_aged))
    assert aged["model"] == key["model"]  # the same MJCF: only the domain tells them apart
    assert aged["domain"]["name"] == "aged" and aged["domain"]["stiffness_scale"] == 0.7


def test_a_teacher_of_another_domain_is_never_taught_nor_overwritten(
    small_xml, tmp_path, monkeypatch, capsys
):
    """--teacher-only for the aged arm in a folder holding the constrained arm's teacher plans
    again and moves the constrained cache aside; --teacher-from refuses the other domain's cache
    naming the fields that differ, and a truncated cache in one line, before any work."""
    model = tmp_path / "arm.xml"
    model.write_text(small_xml)
    out = tmp_path / "run"
    common = ["--model", str(model), "--n-train", "1", "--n-val", "1", "--duration-s", "0.3"]
    common += ["--batch-size", "1", "--hold-factor", "2", "--teacher-only", "--out", str(out)]
    distill.main(common + ["--domain", "constrained"])
    with np.load(out / "teacher.npz") as f:
        constrained = f["c_train"].copy()
    distill.main(common + ["--domain", "aged"])
    assert "other settings (domain.name: stored 'constrained', this run 'aged'" in (
        capsys.readouterr().out
    )
    (aside,) = out.glob("teacher.constrained-*.npz")
    with np.load(aside) as f:
        np.testing.assert_array_equal(f["c_train"], constrained)
    with np.load(out / "teacher.npz") as f:
        assert json.loads(str(f["key"]))["domain"]["name"] == "aged"
        assert not np.array_equal(f["c_train"], constrained)

    def no_work(*args, **kwargs):
        raise AssertionError("work started")

    monkeypatch.setattr(distill.mpc, "track", no_work)
    other = [a if a != str(out) else str(tmp_path / "other") for a in common]
    with pytest.raises(SystemExit) as refused:
        distill.main(
            other + ["--domain", "constrained", "--teacher-from", str(out / "teacher.npz")]
        )
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert refused.value.code == 2 and "planned with other settings" in err
    assert "domain.name: stored 'aged', this run 'constrained'" in err
    assert "domain.stiffness_scale: stored 0.7, this run 1.0" in err
    assert not (tmp_path / "other" / "teacher.npz").exists()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(aside.read_bytes()[:-100])
    monkeypatch.setattr(distill, "start_stage", no_work)  # refused before the arms load
    with pytest.raises(SystemExit) as refused:
        distill.main(other + ["--domain", "constrained", "--teacher-from", str(truncated)])
    err = capsys.readouterr().err.strip().splitlines()
    assert refused.value.code == 2 and "Traceback" not in "".join(err)
    assert "is not a readable teacher cache (truncated or corrupt" in err[-1]


def test_distilled_files_say_what_they_started_from(tmp_path, capsys):
    """A WCGAN-GP start gives method "distill_from_wcgan" (never the CCGAN-GP's "distill"), and
    the file records its start (method, path, payload sha256); it loads as that method. Start
    translators of two methods are refused."""
    wcgan = translator_path().parent.parent / "wcgan" / "translator.ckpt"
    out = tmp_path / "run"
    args = ["--translators", str(wcgan), "--out", str(out), "--n-train", "2", "--n-val", "1"]
    args += ["--duration-s", "0.3", "--epochs", "1", "--batch-size", "2", "--eval-every", "1"]
    args += ["--hold-factor", "2"]
    distill.main(args)
    _, meta = checkpoint.load(out / "translator_seed0.ckpt")
    _, payload = checkpoint.read(wcgan)
    started = {"method": "wcgan", "path": str(wcgan), "sha256": hashlib.sha256(payload).hexdigest()}
    assert meta["method"] == "distill_from_wcgan" and meta["started_from"] == started
    assert meta["finetune"]["method"] == "distill_from_wcgan"
    assert meta["finetune"]["started_from"] == started
    assert "distill_from_wcgan" in METHODS
    load_translator(out / "translator.ckpt", method="distill_from_wcgan")
    with pytest.raises(SystemExit) as mixed:
        distill.main(
            ["--translators", str(translator_path()), str(wcgan), "--out", str(tmp_path / "m")]
        )
    assert mixed.value.code == 2 and "different methods" in capsys.readouterr().err


def test_the_start_method_of_a_file_is_the_method_that_first_made_it():
    from ccgan.distill.cli import distilled_method, start_method

    assert [start_method({"method": m}) for m in ("ccgan", "wcgan", "distill")] == [
        "ccgan",
        "wcgan",
        "ccgan",
    ]
    assert start_method({"method": "distill_from_wcgan"}) == "wcgan"
    assert start_method({"config": {"baseline": True}}) == "wcgan"  # unlabelled (trusted)
    assert start_method({"config": {"baseline": False}}) == "ccgan"
    assert distilled_method("ccgan") == "distill"
    assert distilled_method("wcgan") == "distill_from_wcgan"


def test_translate_refuses_boolean_arrays():
    translator = load_translator()
    poses = np.tile([0.0, 0.0, -0.2, 0.0, 0.0, -1.0], (4, 1))
    with pytest.raises(TypeError, match="pressures are booleans"):
        translator.translate(np.ones((4, 3), bool), poses)
    with pytest.raises(TypeError, match="poses are booleans"):
        translator.translate(np.ones((4, 3)), poses.astype(bool))
    assert translator.translate(np.ones((4, 3)), poses)[0].shape == (4 * translator.k, 3)
