"""Tests of issue 51's translator over a range of media: the conditioned G_c, the k rule per
medium, the media of a distillation, `translate(..., target=...)`, its files, the scoring
helper (`eval.media_range`) and the quick run of `python -m ccgan.distill_range` end to end."""

from __future__ import annotations

import dataclasses
import json
import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjx_arm
from ccgan import checkpoint, distill_range, load_translator
from ccgan.distill_range import cli
from ccgan.distill_range.config import RangeConfig
from ccgan.distill_range.media import sample_training_media, unit_position
from ccgan.media_range import (
    K_GRID,
    MEDIA_RANGE,
    N_CONDITION,
    MediaRange,
    StepTimeModel,
    k_from_step_time,
)
from ccgan.models import with_condition_inputs, with_hidden
from ccgan.translator import TRANSLATORS_DIR, TranslatorMismatchError
from eval import media_range as scoring
from mjx_arm import constants, domains, media
from mjx_arm.identify_family import resolved_viscosity_scale
from mjx_arm.programs import shape_like_programs
from tracking import mpc_mjx
from tracking.held import run_dc, stretch
from tracking.metrics import position_error_cm

K_BY_MEDIUM_JSON = constants.ROOT / "studies/results/cpu/k_by_medium/k_by_medium.json"
#: The committed distilled D_c translator: the default start of a distillation over media.
START = TRANSLATORS_DIR / "ccgan_sim" / "translator_seed0.ckpt"


def study_rows() -> list[dict]:
    """`studies.k_by_medium`'s 14 media: r, s, measured 63% step time and best stretch k."""
    return json.loads(K_BY_MEDIUM_JSON.read_text())["rows"]


def a_range(constrained_scale: float, **changes) -> MediaRange:
    """The issue's range with the step-time model fitted on the study's 14 media."""
    rows = study_rows()
    model = StepTimeModel.fit(*([row[key] for row in rows] for key in ("r", "s", "t63_s")))
    return dataclasses.replace(
        MediaRange((2.0, 30.0), (0.6, 1.0), constrained_scale, model), **changes
    )


@pytest.fixture(scope="module")
def constrained_scale(constrained_arm):
    return resolved_viscosity_scale(constrained_arm)


@pytest.fixture(scope="module")
def program(source_arm):
    """A 2 s shape-like D_s program [20, 3] (bar) and its D_s poses [20, 6]."""
    p = shape_like_programs(1, 2.0, split="test_distill_range")[0].astype(np.float64)
    return p, source_arm.rollout(p, backend="c")


@pytest.fixture(scope="module")
def conditioned(constrained_scale):
    """(the committed distilled D_c translator, it widened to take the condition, zero rows)."""
    plain = load_translator(START)
    generator, params = with_condition_inputs(plain.generator, plain.g_c_params, N_CONDITION)
    wide = dataclasses.replace(
        plain, generator=generator, g_c_params=params, media=a_range(constrained_scale)
    )
    return plain, wide


def first_layer_condition_rows(params, value: float):
    """params with the first LSTM layer's condition rows (its input kernels' last two rows)
    set to `value`."""

    def fill(path, leaf):
        names = [getattr(p, "key", "") for p in path]
        if names[-1] == "kernel" and leaf.shape[0] == 9 + N_CONDITION:
            return leaf.at[9:].set(value)
        return leaf

    return jax.tree_util.tree_map_with_path(fill, params)


def test_a_widened_generator_starts_as_its_start_and_the_condition_changes_its_output(
    conditioned,
):
    plain, wide = conditioned
    x = jnp.asarray(np.random.default_rng(0).uniform(size=(2, 12, 9)), jnp.float32)
    conditions = (np.array([0.0, 1.0]), np.array([0.7, 0.2]))
    want = plain.generator.apply(plain.g_c_params, x)
    for c in conditions:
        x_c = jnp.concatenate([x, jnp.broadcast_to(jnp.asarray(c, jnp.float32), (2, 12, 2))], -1)
        got = wide.generator.apply(wide.g_c_params, x_c)
        # Zero rows: the same sums with two more zero terms, to float32 rounding.
        np.testing.assert_allclose(got, want, atol=1e-6)
    # Condition weights that are not zero: two media, two outputs; one medium, one output.
    params = first_layer_condition_rows(wide.g_c_params, 0.5)
    outs = [
        wide.generator.apply(
            params, jnp.concatenate([x, jnp.broadcast_to(jnp.float32(c), (2, 12, 2))], -1)
        )
        for c in (conditions[0], conditions[1], conditions[0])
    ]
    assert float(jnp.abs(outs[0] - outs[1]).max()) > 1e-2
    np.testing.assert_array_equal(outs[0], outs[2])
    # The generator says what it takes.
    with pytest.raises(ValueError, match="9 features plus its 2 condition"):
        wide.generator.apply(params, x)
    with pytest.raises(ValueError, match="unconditioned G"):
        with_condition_inputs(wide.generator, params, 2)


def test_a_wider_generator_computes_its_starts_output_and_its_new_units_learn(conditioned):
    """`with_hidden`: 32 -> 48 units per layer gives the conditioned start's output; the new
    units' rows into fc and the next gates are zero and get gradients; narrower is refused."""
    _, wide = conditioned
    x = jnp.asarray(np.random.default_rng(1).uniform(size=(2, 12, 11)), jnp.float32)
    params = first_layer_condition_rows(wide.g_c_params, 0.3)  # a condition that acts
    wider, wider_params = with_hidden(wide.generator, params, 48)
    assert wider.hidden == 48 and wider.n_condition == wide.generator.n_condition
    want = wide.generator.apply(params, x)
    np.testing.assert_allclose(wider.apply(wider_params, x), want, atol=1e-6)
    fc_rows = wider_params["params"]["fc"]["kernel"][32:]
    assert float(jnp.abs(fc_rows).max()) == 0.0

    def loss(p):
        return jnp.mean((wider.apply(p, x) - 0.5) ** 2)

    grad = jax.grad(loss)(wider_params)["params"]["fc"]["kernel"][32:]
    assert float(jnp.abs(grad).max()) > 0.0  # the new units run: their rows move at once
    with pytest.raises(ValueError, match="below the trained G's 32"):
        with_hidden(wide.generator, params, 16)
    same, same_params = with_hidden(wide.generator, params, 32)
    assert same is wide.generator and same_params is params


def test_the_rule_gives_each_study_medium_its_best_stretch_k_from_the_others():
    """The step-time model fitted on 13 of the study's media gives the 14th its measured best k
    (`studies.k_by_medium`: stretch only's best on eval's validation program, MuJoCo C)."""
    rows = study_rows()
    for i, row in enumerate(rows):
        others = [r for j, r in enumerate(rows) if j != i]
        model = StepTimeModel.fit(*([r[key] for r in others] for key in ("r", "s", "t63_s")))
        predicted = model.t63_s(row["r"], row["s"])
        assert abs(np.log(predicted / row["t63_s"])) < 0.03, row["medium"]
        assert k_from_step_time(predicted) == row["k"], row["medium"]
        assert k_from_step_time(row["t63_s"]) == row["k"], row["medium"]
    with pytest.raises(ValueError, match=">= 3 media"):
        StepTimeModel.fit([2, 3], [1, 1], [6.7, 9.9])


def test_targets_are_read_as_drag_ratio_and_stiffness(constrained_scale):
    rule = a_range(constrained_scale)
    assert rule.drag_and_stiffness(domains.CONSTRAINED) == pytest.approx((10.0, 1.0))
    assert rule.drag_and_stiffness(domains.AGED) == pytest.approx((10.0, 0.7))
    water = mjx_arm.Domain(viscosity_scale=media.viscosity_scale_of(3.0, constrained_scale))
    assert rule.drag_and_stiffness(water) == pytest.approx((3.0, 1.0))
    assert rule.drag_and_stiffness((30, 0.6)) == (30.0, 0.6)
    np.testing.assert_allclose(rule.condition(2.0, 0.6), [0.0, 0.0])
    np.testing.assert_allclose(rule.condition(30.0, 1.0), [1.0, 1.0])
    np.testing.assert_allclose(rule.condition(np.sqrt(60.0), 1.0), [0.5, 1.0], atol=1e-6)
    # D_c by the rule: 15, the study's best there. The aged arm's step time fits to 45.7 s,
    # so 25, between the study's best at (10, 0.8) and (10, 0.6), 20 and 30.
    assert rule.step_time.t63_s(10.0, 0.7) == pytest.approx(45.7, abs=0.1)
    assert rule.hold_factor(10.0, 1.0) == 15 and rule.hold_factor(10.0, 0.7) == 25
    assert rule.hold_factor(10.0, 0.7, t63_s=36.2) == 20  # a measured step time wins
    with pytest.raises(ValueError, match=r"drag ratio 1\.5 is outside .* \[2, 30\]"):
        rule.drag_and_stiffness((1.5, 0.8))
    with pytest.raises(ValueError, match=r"stiffness scale 1\.2 is outside"):
        rule.drag_and_stiffness(dataclasses.replace(domains.CONSTRAINED, stiffness_scale=1.2))
    with pytest.raises(ValueError, match="viscosity or mass_scale"):
        rule.drag_and_stiffness(mjx_arm.Domain(viscosity=1.0))
    with pytest.raises(TypeError, match="Domain or a pair"):
        rule.drag_and_stiffness("water")
    with pytest.raises(TypeError, match="real number"):
        rule.drag_and_stiffness((True, 0.8))
    with pytest.raises(ValueError, match="step time"):
        rule.hold_factor(10.0, 1.0, t63_s=-1.0)


def test_translate_takes_a_target_only_when_conditioned(conditioned, program, constrained_scale):
    plain, wide = conditioned
    p, x = program
    commands, k = wide.translate(p, x, target=(10.0, 0.7))
    assert k == 25 and commands.shape == (len(p) * k, 3)
    # Zero condition rows: D_c's translation held the aged arm's k.
    np.testing.assert_allclose(commands[::k], plain.translate(p, x)[0][:: plain.k], atol=1e-5)
    _, k_water = wide.translate(p, x, target=mjx_arm.Domain(viscosity_scale=constrained_scale / 5))
    assert k_water == 5  # r = 2: t63 6.7 s
    assert wide.translate(p, x, target=(10.0, 1.0), t63_s=50.0)[1] == 25
    with pytest.raises(TypeError, match="conditioned on the target medium"):
        wide.translate(p, x)
    with pytest.raises(TypeError, match="one pair of media at k = 15: it takes no target"):
        plain.translate(p, x, target=(10.0, 1.0))
    with pytest.raises(ValueError, match="outside the range"):
        wide.translate(p, x, target=(40.0, 1.0))


def test_a_conditioned_file_round_trips_with_its_labels_and_range(
    conditioned, program, tmp_path, constrained_scale
):
    _, wide = conditioned
    params = first_layer_condition_rows(wide.g_c_params, 0.3)
    source = checkpoint.load(START)
    rule = a_range(constrained_scale, training_media=((3.0, 0.7),), held_out_media=((2.0, 1.0),))
    tree, meta = cli.conditioned_checkpoint(
        source, wide, params, rule, "bd815f3421fffcd2", {"note": "test"}
    )
    path = checkpoint.save(tmp_path / "range.ckpt", tree, meta)
    loaded = load_translator(path, method="distill_range", target_domain=MEDIA_RANGE)
    assert loaded.conditioned and loaded.media == rule and loaded.f_c_params is None
    assert loaded.generator.n_condition == N_CONDITION
    assert loaded.media.training_media == ((3.0, 0.7),)
    assert meta["finetune"] == {"note": "test"} and meta["finetune_earlier"]  # the start's
    p, x = program
    in_memory = dataclasses.replace(wide, g_c_params=params, media=rule)
    for target in ((3.0, 0.7), (20.0, 0.9)):
        np.testing.assert_array_equal(
            loaded.translate(p, x, target=target)[0], in_memory.translate(p, x, target=target)[0]
        )
    with pytest.raises(TranslatorMismatchError, match="expects target_domain 'constrained'"):
        load_translator(path, target_domain="constrained")
    # A file whose G_c and range disagree is refused whole.
    for broken in (
        meta | {"generator": meta["generator"] | {"n_condition": 0}},
        {key: v for key, v in meta.items() if key != MEDIA_RANGE},
    ):
        bad = checkpoint.save(tmp_path / "bad.ckpt", tree, broken)
        with pytest.raises(checkpoint.CheckpointError, match="condition features"):
            load_translator(bad)


def test_training_media_are_spread_and_kept_away_from_the_held_out():
    cfg = RangeConfig()
    points = sample_training_media(cfg)
    assert len(points) == 24 and points == sample_training_media(cfg)
    assert points != sample_training_media(dataclasses.replace(cfg, media_seed=1))
    units = np.array([unit_position(cfg, r, s) for r, s in points])
    held = np.array([unit_position(cfg, r, s) for r, s in cfg.held_out_media])
    assert ((units >= 0) & (units <= 1)).all()
    # A Latin hypercube: one point in each row and each column of the 24 x 24 grid.
    for axis in (0, 1):
        assert sorted(np.floor(units[:, axis] * 24).astype(int)) == list(range(24))
    gaps = np.linalg.norm(units[:, None] - held[None], axis=-1)
    assert gaps.min() >= cfg.min_separation
    assert (2.0, 0.6) in cfg.held_out_media and (10.0, 0.7) in cfg.held_out_media
    with pytest.raises(distill_range.config.ConfigError, match="outside the range"):
        RangeConfig(held_out=(40.0, 1.0))
    with pytest.raises(distill_range.config.ConfigError, match="pairs"):
        RangeConfig(held_out=(10.0,))


def test_the_cli_refuses_bad_settings_before_any_work(tmp_path, capsys):
    for argv, message in (
        (["--quick", "--n-media", "2"], "--n-media must be >= 3"),
        (["--quick", "--held-out", "9", "1"], "--held-out medium (9, 1) is outside the range"),
        (["--quick", "--translators", str(tmp_path / "none.ckpt")], "no checkpoint at"),
        (["--quick", "--seeds", "0", "1"], "one seed per translator file"),
        (["--quick", "--generator-hidden", "16"], "at least the start's 32"),
    ):
        with pytest.raises(SystemExit) as exc:
            distill_range.main([*argv, "--out", str(tmp_path / "o")])
        assert exc.value.code == 2 and message in capsys.readouterr().err
        assert not (tmp_path / "o").exists()


def test_a_second_writer_of_one_folder_is_refused_before_any_work(tmp_path, capsys):
    from test_run_folder import held_by_another_process

    with held_by_another_process(tmp_path / "o", beside=True) as pid:
        with pytest.raises(SystemExit) as exc:
            distill_range.main(["--quick", "--out", str(tmp_path / "o")])
    assert exc.value.code == 2 and f"in use by process {pid}" in capsys.readouterr().err


def test_scoring_runs_each_medium_in_its_own_arm_at_the_rules_k(
    conditioned, source_arm, constrained_arm, constrained_scale
):
    """`eval.media_range.score_media` against the same X_err computed here: each medium's arm
    loaded on its own, the translator's commands (zero condition rows: the D_c translator's)
    and the D_s program held the rule's k."""
    plain, wide = conditioned
    rule = a_range(constrained_scale, training_media=((2.0, 1.0),))
    wide = dataclasses.replace(wide, media=rule)
    pressures = shape_like_programs(2, 2.0, split="test_distill_range").astype(np.float64)
    targets = source_arm.rollout(pressures, backend="c")
    rows = scoring.score_media(
        [wide], constrained_arm, [(2.0, 1.0), (10.0, 0.7)], pressures, targets,
        references=[(10.0, 0.7, "D_c's", plain), (10.0, 0.7, "twice", [plain, plain])],
        log=lambda *_: None,
    )  # fmt: skip
    # A reference given as its seeds' translators is their mean: two of one file, that file.
    assert rows[1]["x_err_cm"]["twice"] == rows[1]["x_err_cm"]["D_c's"]
    for row in rows:
        row["x_err_cm"].pop("twice", None)
    assert [row["role"] for row in rows] == ["training", "other"]
    for row, (r, s, k) in zip(rows, ((2.0, 1.0, 5), (10.0, 0.7, 25)), strict=True):
        arm = mjx_arm.load(
            domain=mjx_arm.Domain(
                viscosity_scale=media.viscosity_scale_of(r, constrained_scale), stiffness_scale=s
            )
        )
        assert row["k"] == row["k_measured"] == k  # the study's (2, 1) t63 6.7 s gives 5
        pairs = zip(pressures, targets, strict=True)
        held = stretch(np.stack([plain.translate(p, x)[0][:: plain.k] for p, x in pairs]), k)
        want = position_error_cm(run_dc(arm, held, k, "c"), targets).mean()
        assert row["x_err_cm"]["conditioned_mean"] == pytest.approx(want, rel=1e-4)
        want = position_error_cm(run_dc(arm, stretch(pressures, k), k, "c"), targets).mean()
        assert row["x_err_cm"]["stretch"] == pytest.approx(want, rel=1e-9)
    # The reference is scored at its medium only, at its own k (15).
    assert "D_c's" not in rows[0]["x_err_cm"]
    own = np.stack([plain.translate(p, x)[0] for p, x in zip(pressures, targets, strict=True)])
    want = position_error_cm(run_dc(arm, own, 15, "c"), targets).mean()
    assert rows[1]["x_err_cm"]["D_c's"] == pytest.approx(want, rel=1e-9)
    lines = scoring.table_lines(rows, ["D_c's"])
    assert lines[2].startswith("| 2 | 1 | training | 6.6 / 6.7 | 5 / 5 |")  # fit / measured


@pytest.mark.slow  # about 2.5 min on one core: two MJX tracker compiles (docs/testing.md)
def test_the_quick_run_end_to_end(tmp_path, monkeypatch, capsys):
    """`python -m ccgan.distill_range --quick`, then `python -m eval.media_range` on it: one
    teacher call per k, each program planned in its own training medium (no held-out one), the
    files labelled and conditioned, the condition changing the translation."""
    calls = []
    track = mpc_mjx.track

    def spy(arm_c, targets, k, init, cfg, **kw):
        calls.append((k, np.exp(np.asarray(kw["media"][1]))))
        return track(arm_c, targets, k, init, cfg, **kw)

    monkeypatch.setattr(mpc_mjx, "track", spy)
    out = tmp_path / "range"
    distill_range.main(["--out", str(out), "--quick"])
    printed = capsys.readouterr().out
    assert "held-out X_err" in printed and "wrote" in printed
    run = json.loads((out / "distill_range.json").read_text())
    history = run["history"]
    training = [(m["r"], m["s"], m["k"]) for m in history["media"]]
    ks = sorted({k for *_, k in training})
    assert [k for k, _ in calls] == ks and len(ks) >= 2  # one call per k (quick: 5 and 10)
    constrained = run["media_range"]["constrained_viscosity_scale"]
    for k, values in calls:
        # Each program's medium (viscosity scale, s): one of this k's training media, and each
        # of those has its 3 programs (2 training, 1 held-out) in the call.
        mine = np.array(
            [[media.viscosity_scale_of(r, constrained), s] for r, s, mk in training if mk == k]
        )
        match = np.isclose(values[:, None], mine[None], rtol=1e-5).all(-1)  # [programs, media]
        assert (match.sum(1) == 1).all() and (match.sum(0) == 3).all()
    for r, s, k in training:
        arm = mjx_arm.load(domain=media.medium_domain(r, s, constrained))
        assert k == k_from_step_time(media.step_t63_s(arm, media.step_hold_s(r, s)), K_GRID)
    # The kept iterate is never worse than the start on the training media's held-out programs.
    assert all(
        b <= a
        for a, b in zip(history["val_x_err_cm_before"], history["best_val_x_err_cm"], strict=True)
    )  # noqa: E501
    assert history["teacher_val_x_err_cm"]["score"] < history["stretch_val_x_err_cm"]["score"]
    translator = load_translator(out / "translator.ckpt", method="distill_range",
                                 target_domain=MEDIA_RANGE)  # fmt: skip
    assert translator.media.held_out_media == ((2.0, 1.0), (3.2, 0.9))
    p = shape_like_programs(1, 2.0, split="test_distill_range")[0].astype(np.float64)
    x = mjx_arm.load(domain="source").rollout(p, backend="c")
    a, k_a = translator.translate(p, x, target=(2.0, 1.0))
    b, k_b = translator.translate(p, x, target=(2.0, 0.8))
    assert k_a == k_b == 5 and np.abs(a - b).max() > 1e-4  # trained condition rows
    # A stopped training goes on from its next epoch, on the cached teacher (no planning).
    calls.clear()
    _, a, range_config, config = cli.parse(["--out", str(out), "--quick", "--epochs", "4"])
    arm_s, arm_c = (mjx_arm.load(domain=d) for d in ("source", "constrained"))
    _, start = cli.start_translators(None, a, arm_c.model_hash)
    training_media, rule = distill_range.plan_media(range_config, arm_c, log=lambda *_: None)
    state = out / "training_state.npz"
    stop = threading.Event()
    _, stopped = distill_range.distill_range(
        start, arm_s, arm_c, training_media, rule, config, cache=out / "teacher.npz",
        progress=False, on_validation=lambda *_: stop.set(), stop=stop, resume=state,
    )  # fmt: skip
    # Set during epoch 1's validation, as a SIGTERM would be: seen after epoch 2.
    assert not stopped["complete"] and len(stopped["train_loss"]) == 2 and state.exists()
    logs = []
    _, resumed = distill_range.distill_range(
        start, arm_s, arm_c, training_media, rule, config, cache=out / "teacher.npz",
        progress=False, log=logs.append, resume=state,
    )  # fmt: skip
    assert any("resuming" in line and "2 of 4 epochs" in line for line in logs)
    assert resumed["complete"] and len(resumed["train_loss"]) == 4 and not state.exists()
    assert resumed["train_loss"][:2] == stopped["train_loss"] and not calls
    scored = tmp_path / "score" / "media"
    seeds = [str(out / f"translator_seed{s}.ckpt") for s in (0, 1, 2)]
    scoring.main(["--translators", *seeds, "--out", str(scored), "--n-programs", "1",
                  "--duration", "2"])  # fmt: skip
    result = json.loads(scored.with_suffix(".json").read_text())
    roles = [row["role"] for row in result["rows"]]
    assert roles == ["held out", "held out", "training", "training", "training"]
    assert all(len(row["x_err_cm"]["conditioned"]) == 3 for row in result["rows"])
    assert scored.with_suffix(".png").stat().st_size > 0
    assert "| 2 | 1 | held out |" in scored.with_suffix(".md").read_text()


def test_held_out_scores_are_the_same_with_media_scored_at_once(
    source_arm, constrained_scale, monkeypatch
):
    """`media_x_err_cm` on a host of many cores scores several media at once, each in its own
    thread pool: the same X_err, to the bit, as one medium after another on one core."""
    from ccgan.distill_range.imitation import RangeData, media_x_err_cm
    from ccgan.distill_range.media import Medium

    chosen = [Medium(2.0, 1.0, 6.7, 5), Medium(10.0, 0.7, 47.0, 25), Medium(5.0, 0.9, 18.0, 10)]
    arms = [
        mjx_arm.load(
            domain=mjx_arm.Domain(
                viscosity_scale=media.viscosity_scale_of(m.drag_ratio, constrained_scale),
                stiffness_scale=m.stiffness_scale,
            )
        )
        for m in chosen
    ]
    pressures = shape_like_programs(3, 1.0, split="test_media_at_once").astype(np.float64)
    targets = source_arm.rollout(pressures, backend="c")
    data = RangeData(
        s_train=None, c_train=None, s_val=None, x_val=targets, p_val=pressures, c_val=pressures,
        medium_val=np.array([0, 1, 2]), window=4,
    )  # fmt: skip
    commands = np.stack([pressures, 0.9 * pressures])  # two "seeds"
    monkeypatch.setenv("SOFTARM_THREADS", "1")
    one_by_one = media_x_err_cm(arms, chosen, commands, data)
    monkeypatch.setenv("SOFTARM_THREADS", "6")  # 2 trajectories a medium: 3 media at once
    at_once = media_x_err_cm(arms, chosen, commands, data)
    for a, b in zip(one_by_one, at_once, strict=True):
        assert a.shape == (2, 3)
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(one_by_one[1][:, 0], one_by_one[1][:, 1])  # media differ


def test_step_times_are_the_same_measured_at_once(constrained_arm, monkeypatch):
    """`measure_media` runs the media's step tests at once, a thread each: the same step times
    as one after another, to the bit, and the rule's k from them (the study's (2, 1): k = 5)."""
    from ccgan.distill_range.media import measure_media

    points = [(2.0, 1.0), (2.5, 0.9), (3.0, 1.0)]
    monkeypatch.setenv("SOFTARM_THREADS", "1")
    one_by_one = measure_media(constrained_arm, points, log=lambda _: None)
    monkeypatch.setenv("SOFTARM_THREADS", "3")
    at_once = measure_media(constrained_arm, points, log=lambda _: None)
    assert at_once == one_by_one and at_once[0].k == 5
    assert at_once[1].t63_s > at_once[0].t63_s  # softer and slower than (2, 1)


def test_runs_of_other_media_merge_into_one_table(tmp_path, capsys):
    """`python -m eval.media_range --merge`: two runs' media in one table (the per-medium
    translator's column and its ratio where one was scored) and plot; parts of other
    translators, or scoring one medium twice, are refused."""

    def row(r, s, refs=None):
        x = {"conditioned": [0.2, 0.4], "conditioned_mean": 0.3, "stretch": 0.6} | (refs or {})
        return {
            "r": r, "s": s, "role": "held out", "t63_fit_s": 30.0, "t63_measured_s": 30.5,
            "k": 15, "k_measured": 15, "x_err_cm": x, "per_program_cm": {},
        }  # fmt: skip

    shared = {"translators": ["a.ckpt", "b.ckpt"], "model": "m.xml", "programs": ["p0"]}
    shared |= {"duration_s": 60.0, "media_range": {"drag_ratio_range": [2.0, 30.0]}}
    parts = [
        shared | {"machine": "cpu A", "command": "c1", "wall_s": 10.0,
                  "rows": [row(10.0, 1.0, {"per-medium D_c": 0.2})]},
        shared | {"machine": "cpu A", "command": "c2", "wall_s": 5.0, "rows": [row(2.0, 0.6)]},
    ]  # fmt: skip
    paths = []
    for i, part in enumerate(parts):
        paths.append(str(tmp_path / f"part{i}.json"))
        (tmp_path / f"part{i}.json").write_text(json.dumps(part))
    scoring.main(["--merge", *paths, "--out", str(tmp_path / "all")])
    table = (tmp_path / "all.md").read_text()
    assert "| 10 | 1 | held out |" in table and "| 2 | 0.6 | held out |" in table
    assert "per-medium D_c | conditioned / per-medium |" in table and "| 0.200 | 1.50 |" in table
    merged = json.loads((tmp_path / "all.json").read_text())
    assert merged["wall_s"] == 15.0 and len(merged["rows"]) == 2
    assert (tmp_path / "all.png").stat().st_size > 0
    (tmp_path / "other.json").write_text(json.dumps(parts[1] | {"translators": ["c.ckpt"]}))
    with pytest.raises(SystemExit):
        scoring.main(["--merge", paths[0], str(tmp_path / "other.json"), "--out", "x"])
    assert "differs from" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        scoring.main(["--merge", paths[0], paths[0], "--out", "x"])
    assert "more than one part" in capsys.readouterr().err


def test_a_reference_is_scored_over_its_seeds_files(tmp_path, capsys):
    """`--reference R S FILE` reads the translator_seed<s>.ckpt beside FILE (the committed
    aged_sim's three) and labels the column with their number."""
    aged = "results/paper/rerun_2026-11-27/run/aged_sim/translator.ckpt"
    translator = "studies/results/h200/media_range/range/translator_seed0.ckpt"
    scoring.main([
        "--translators", translator, "--out", str(tmp_path / "t"), "--media", "10", "0.7",
        "--n-programs", "1", "--duration", "2", "--reference", "10", "0.7", aged,
    ])  # fmt: skip
    row = json.loads((tmp_path / "t.json").read_text())["rows"][0]
    assert "per-medium aged_sim (k 25, 3 seeds)" in row["x_err_cm"]


def test_the_preset_configs_are_the_cli_runs_own(tmp_path, monkeypatch):
    """`cli.preset_configs` (the studies' way to read a run's settings) gives what a run of the
    command with no other flags parses, and writes and locks nothing."""
    for quick in (False, True):
        argv = [*(["--quick"] if quick else []), "--out", str(tmp_path / "runs" / f"o{quick}")]
        _, _, range_config, config = cli.parse(argv)
        monkeypatch.chdir(tmp_path / "runs")
        before = sorted(p.name for p in (tmp_path / "runs").iterdir())
        assert cli.preset_configs(quick) == (range_config, config)
        assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == before
    assert config.teacher_backend == "mjx" and range_config.n_media == 3
