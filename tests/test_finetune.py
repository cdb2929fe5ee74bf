"""Tests of ccgan.finetune: G_c fine-tuned through the MJX rollout (3-segment arm, CPU)."""

import dataclasses

import jax
import numpy as np
import pytest

import mjx_arm
from ccgan import checkpoint, finetune, load_translator
from ccgan.translator import SOLID_TRANSLATORS_DIR

#: The solid-disc arm's CCGAN-GP: its files record no arm, so it runs on the 3-segment test arm.
SOLID_CCGAN = SOLID_TRANSLATORS_DIR / "ccgan" / "translator.ckpt"


@pytest.fixture(scope="module")
def arms():
    xml = mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))
    return mjx_arm.load(xml=xml, domain="source"), mjx_arm.load(xml=xml, domain="constrained")


@pytest.mark.slow  # about 2 min on 2 cores (docs/testing.md)
def test_finetune_lowers_the_window_error_and_writes_a_translator(arms, tmp_path):
    arm_s, arm_c = arms
    shipped = load_translator(SOLID_CCGAN, trust_unlabelled=True)  # its files have no labels
    config = finetune.FinetuneConfig(
        steps=4,
        batch_size=4,
        window_s=0.5,
        n_train=8,
        n_val=4,
        learning_rates=(1e-3, 10.0),
        anchor_weights=(0.0,),
        eval_every=2,
        anchor_s=1.0,
        n_anchor=4,
        val_long_s=1.5,
    )
    reports = []

    def on_validation(best, hist):
        reports.append((hist["complete"], list(hist["best_step"]), best[0]))

    params, history = finetune.finetune(
        [shipped], arm_s, arm_c, config, progress=False, on_validation=on_validation
    )
    # The best iterates so far were reported after every validation but the first (steps 2, 4),
    # the last report being the returned result.
    assert [r[0] for r in reports] == [False, False] and history["complete"]
    assert reports[-1][1] == history["best_step"]
    for got, want in zip(jax.tree.leaves(reports[-1][2]), jax.tree.leaves(params[0]), strict=True):
        np.testing.assert_array_equal(got, want)
    assert len(params) == 1 and history["members"] == [(0, 1e-3, 0.0), (0, 10.0, 0.0)]
    assert np.asarray(history["train_loss"]).shape == (4, 2)
    assert sorted(history["val_x_err_cm"]) == [0, 2, 4]
    # Where the simulator's gradient reaches (the window programs) two steps at the sane step
    # size lower the held-out error; the kept iterate is never worse than the trained
    # translator and is the one the history names.
    window = np.asarray(history["val_window_x_err_cm"])
    assert window.shape == (3, 2) and window[1, 0] < window[0, 0]
    assert history["best_val_x_err_cm"][0] <= history["val_x_err_cm_before"][0]
    best = (0, history["best_learning_rate"][0], history["best_anchor_weight"][0])
    m = history["members"].index(best)
    assert history["best_val_x_err_cm"][0] == history["val_x_err_cm"][history["best_step"][0]][m]

    # Scored again in MuJoCo C from the returned parameters: the same held-out score, the mean
    # of the window programs' and the long programs' X_err.
    tuned = dataclasses.replace(shipped, g_c_params=params[0])
    errs, first = [], None
    for split, duration in (("val", None), ("val_long", config.val_long_s)):
        p_val = finetune.training_programs(config, config.n_val, split, duration)
        x_val = arm_s.rollout(p_val, backend="c")
        pairs = zip(p_val, x_val, strict=True)
        cmds = np.stack([tuned.translate(p, x)[0][:: tuned.k] for p, x in pairs])
        errs.append(finetune.x_err_cm_c(arm_c, cmds, tuned.k, x_val))
        # Several members' commands [M, B, T, 3] in one batch: one score per member.
        both = finetune.x_err_cm_c(arm_c, np.stack([cmds, cmds[::-1]]), tuned.k, x_val)
        assert both.shape == (2,)
        np.testing.assert_allclose(both[0], errs[-1], rtol=1e-12)
        first = first or (p_val[0], x_val[0], cmds[0])
    assert p_val.shape[1] == round(10 * config.val_long_s)
    np.testing.assert_allclose(np.mean(errs), history["best_val_x_err_cm"][0], rtol=1e-4)

    # Written as a translator file: G_c replaced, F_c, k and bounds kept, settings recorded.
    src = SOLID_CCGAN
    path = finetune.save_finetuned(tmp_path / "t.ckpt", src, params[0], {"config": "x"})
    loaded = load_translator(path, trust_unlabelled=True)
    assert loaded.k == shipped.k and loaded.f_c_params is not None
    np.testing.assert_allclose(loaded.bounds.low, shipped.bounds.low)
    _, meta = checkpoint.load(path)
    assert meta["finetune"] == {"config": "x"} and "finetune_earlier" not in meta
    # A second stage from that file keeps the first stage's record.
    again = finetune.save_finetuned(tmp_path / "t2.ckpt", path, params[0], {"config": "y"})
    _, meta2 = checkpoint.load(again)
    assert meta2["finetune"] == {"config": "y"}
    assert meta2["finetune_earlier"] == [{"config": "x"}]
    out, _ = loaded.translate(first[0], first[1])
    np.testing.assert_allclose(out[:: loaded.k], first[2], rtol=1e-5, atol=1e-6)


def test_finetune_rejects_translators_with_different_k(arms):
    shipped = load_translator()
    other = dataclasses.replace(shipped, k=shipped.k + 5)
    with pytest.raises(ValueError, match="disagree on k"):
        finetune.finetune([shipped, other], *arms, finetune.FinetuneConfig(steps=1))
    # With hold_factor, both are fine-tuned (and written) at that k.
    assert finetune.hold_factor([shipped, other], finetune.FinetuneConfig(hold_factor=2)) == 2
    assert finetune.hold_factor([shipped], finetune.FinetuneConfig()) == shipped.k


def test_finetune_program_families():
    from mjx_arm.programs import shape_like_programs

    config = finetune.FinetuneConfig(programs="shape_like", window_s=1.0, seed=2)
    got = finetune.training_programs(config, 3, "val")
    np.testing.assert_array_equal(got, shape_like_programs(3, 1.0, seed=2, split="finetune/val"))
    assert finetune.training_programs(config, 2, "anchor", 5.0).shape == (2, 50, 3)
    babble = finetune.training_programs(dataclasses.replace(config, programs="babble"), 3, "val")
    assert babble.shape == got.shape and not np.allclose(babble, got)
    with pytest.raises(ValueError, match="programs must be one of"):
        finetune.FinetuneConfig(programs="shapes")


def test_finetune_cli_asks_for_a_hold_factor_when_the_seeds_disagree(tmp_path, capsys):
    """The chain's CCGAN-GP seeds chose k = 15 and 20: refused before any work without
    --hold-factor."""
    chain = "studies/results/h200/issue29/chain/ccgan"
    argv = ["--translators", f"{chain}/translator_seed0.ckpt", f"{chain}/translator_seed1.ckpt",
            "--model", "models/softarm.xml", "--out", str(tmp_path / "out")]  # fmt: skip
    with pytest.raises(SystemExit) as exit_:
        finetune.main(argv)
    assert exit_.value.code == 2
    assert "disagree on k: [15, 20]: give --hold-factor" in capsys.readouterr().err
    assert not list(tmp_path.glob("out/*.ckpt"))
