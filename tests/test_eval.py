"""Tests of eval/: shape programs, metrics, and a tiny end-to-end run (3-segment arm, CPU)."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import eval  # noqa: F401  (first: sets MUJOCO_GL before mujoco is imported)
import mjx_arm  # (before jax)
from ccgan.losses import tracking_loss
from eval import metrics, mpc, pipeline, render, shapes


@pytest.fixture(scope="module")
def small_xml():
    return mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))


@pytest.mark.parametrize("name", list(shapes.SHAPES))
def test_shape_programs_in_valve_range(name):
    p = shapes.SHAPES[name](60.0)
    assert p.shape == (600, 3)
    assert np.isfinite(p).all()
    assert p.min() >= shapes.P_LOW_BAR and p.max() <= shapes.P_HIGH_BAR
    # Every shape moves: each chamber swings by at least 1 bar.
    assert (np.ptp(p, axis=0) > 1.0).all()


@pytest.mark.parametrize("name", shapes.PERIODIC_SHAPES)
def test_periodic_shapes_repeat_every_30_s(name):
    p = shapes.SHAPES[name](60.0)
    np.testing.assert_allclose(p[:300], p[300:], atol=1e-9)
    assert not np.allclose(p[:150], p[150:300])  # ...and not with half the period


def test_circle_is_three_phased_sinusoids():
    p = shapes.circle(60.0)
    t = np.arange(600) / 10.0
    expected0 = shapes.P_MID_BAR + shapes.AMPLITUDE_BAR * np.sin(2 * np.pi * t / 30.0)
    np.testing.assert_allclose(p[:, 0], expected0, atol=1e-12)
    # Chamber 1 lags chamber 0 by 120 deg = 10 s = 100 steps.
    np.testing.assert_allclose(p[100:, 1], p[:-100, 0], atol=1e-9)
    # Phases 0/120/240: the mean pressure is constant (pure bending).
    np.testing.assert_allclose(p.mean(axis=1), shapes.P_MID_BAR, atol=1e-9)


def test_damped_circle_shrinks():
    p = shapes.damped_circle(60.0)
    assert np.ptp(p[-300:], axis=0).max() < 0.6 * np.ptp(p[:300], axis=0).max()


def test_shape_like_programs_in_range_reproducible_and_never_a_test_shape():
    p = shapes.shape_like_programs(64, 60.0, seed=3, split="train")
    assert p.shape == (64, 600, 3) and p.dtype == np.float32 and np.isfinite(p).all()
    lo, hi = shapes.P_MID_BAR - shapes.AMPLITUDE_BAR, shapes.P_MID_BAR + shapes.AMPLITUDE_BAR
    assert p.min() >= lo - 1e-5 and p.max() <= hi + 1e-5
    # Program i does not depend on how many are drawn; other seeds and splits differ.
    np.testing.assert_array_equal(shapes.shape_like_programs(5, 60.0, seed=3)[:], p[:5])
    assert not np.allclose(shapes.shape_like_programs(5, 60.0, seed=4), p[:5])
    assert not np.allclose(shapes.shape_like_programs(5, 60.0, seed=3, split="val"), p[:5])
    # Every program moves, and at least one is a staircase (holds for >= 5 steps at a time)
    # and one is smooth (changes at every step).
    assert (np.ptp(p, axis=1).max(axis=-1) > 0.05).all()
    changes = np.abs(np.diff(p, axis=1)).max(axis=-1) > 1e-6  # [64, 599]
    assert (changes.mean(axis=1) < 0.2).any() and changes.all(axis=1).any()
    # Some add a common-mode offset (the mean pressure leaves P_MID), some do not.
    mean_offset = np.abs(p.mean(axis=2) - shapes.P_MID_BAR).max(axis=1)
    assert (mean_offset > 0.1).any() and (mean_offset < 1e-4).any()
    # None is one of the five test shapes.
    for fn in shapes.SHAPES.values():
        assert np.abs(p - fn(60.0)[None]).max(axis=(1, 2)).min() > 0.1
    # Full scale: the same draws scaled up to the amplitude limit, still in range.
    full = shapes.shape_like_programs(64, 60.0, seed=3, split="train", full_scale=True)
    assert full.min() >= lo - 1e-5 and full.max() <= hi + 1e-5
    peak, peak_full = (np.abs(x - shapes.P_MID_BAR).max(axis=(1, 2)) for x in (p, full))
    assert (peak_full >= peak - 1e-5).all() and (peak_full > peak + 0.1).mean() > 0.3


def test_position_error_by_hand():
    pred = np.array([[0.0, 0.0, 0.0, 0, 0, 1], [0.03, 0.04, 0.0, 0, 0, 1]])
    target = np.zeros((2, 6))
    target[:, 5] = 1.0
    # ||(0.03, 0.04, 0)|| = 0.05 m = 5 cm.
    np.testing.assert_allclose(metrics.position_error_cm(pred, target), [0.0, 5.0])


def test_orientation_error_by_hand():
    d3 = np.array([[0, 0, 1], [0, 1, 0], [0, 0, -1], [1, 1, 0]], dtype=float)
    pred = np.concatenate([np.zeros((4, 3)), d3], axis=1)
    target = np.tile([0, 0, 0, 0, 0, 1.0], (4, 1))
    target[3, 3:] = [1, 0, 0]
    # Same: 0; perpendicular: pi/2; opposite: pi; (1,1,0) unnormalised vs (1,0,0): 45 deg.
    np.testing.assert_allclose(
        metrics.orientation_error_rad(pred, target), [0, np.pi / 2, np.pi, np.pi / 4], atol=1e-7
    )
    # Rounding that pushes the cosine past 1 must not give NaN.
    almost = np.array([[0, 0, 0, 0, 0, 1 + 1e-15]])
    assert metrics.orientation_error_rad(almost, target[:1])[0] == 0.0


def test_mean_std_and_summary():
    assert metrics.mean_std([1.0, 3.0]) == (2.0, 1.0)
    assert metrics.format_mean_std([1.0, 3.0]) == "2.00 ± 1.00"
    reps = np.zeros((2, 4, 6))
    reps[1, :, 0] = 0.02  # the two runs are 2 cm apart: each is 1 cm from the mean
    spread = metrics.repetition_spread_cm(reps)
    assert spread["spread_cm_mean"] == pytest.approx(1.0)
    assert spread["spread_cm_max"] == pytest.approx(1.0)


def test_stretch_and_every_kth():
    p = np.arange(6.0).reshape(2, 3)
    s = pipeline.stretch(p, 3)
    assert s.shape == (6, 3)
    np.testing.assert_array_equal(s[:3], np.tile(p[0], (3, 1)))
    poses = np.arange(12.0)[:, None].repeat(6, axis=1)
    np.testing.assert_array_equal(pipeline.every_kth(poses, 4)[:, 0], [3, 7, 11])


def test_noise_is_clipped_and_zero_mean():
    p = np.full((4000, 3), 1.75)
    noisy = pipeline.add_noise(p, 0.1, seed=0)
    assert noisy.min() >= 0 and noisy.max() <= 3.5
    assert abs(noisy.mean() / 3.5 - 0.5) < 0.01
    assert abs((noisy / 3.5).std() - 0.1) < 0.01
    np.testing.assert_array_equal(noisy, pipeline.add_noise(p, 0.1, seed=0))


def test_replay_matches_rollout(small_xml):
    arm = mjx_arm.load(xml=small_xml, domain="source")
    p = shapes.circle(2.0)
    qpos, poses = render.replay(arm, p)
    np.testing.assert_allclose(poses, arm.rollout(p, backend="c"), atol=1e-12)
    # The joint positions are those of the poses: forward kinematics gives the same tip.
    import mujoco

    data = mujoco.MjData(arm.mj_model)
    for t in (0, len(p) // 2, len(p) - 1):
        data.qpos[:] = qpos[t]
        mujoco.mj_kinematics(arm.mj_model, data)
        np.testing.assert_allclose(data.site_xpos[arm.tip_site_id], poses[t, :3], atol=1e-12)


def test_tiny_end_to_end(small_xml, tmp_path, capsys):
    import shutil

    # A WCGAN-GP stand-in with one model per training seed (copies of the shipped translator),
    # so the per-seed path runs through the table, the noise and the periodicity tests.
    shipped = Path(__file__).resolve().parent.parent / "results" / "ccgan" / "translator.ckpt"
    (tmp_path / "wcgan").mkdir()
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(shipped, tmp_path / "wcgan" / name)
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "stretch", "ccgan", "wcgan"),
        seeds=(0, 1),
        wcgan_path=str(tmp_path / "wcgan" / "translator.ckpt"),
        duration_s=2.0,
        stretch_candidates=(1, 2),
        validation_duration_s=1.0,
        noise_stds=(0.1,),
        n_repeats=2,
        render=True,
        out_dir=str(tmp_path),
        xml=small_xml,
        video_speedup=1.0,
        video_fps=10,
        video_panel_hw=(96, 128),
    )
    results = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    data = json.loads((tmp_path / "shapes.json").read_text())
    row = data["table"]["circle"]["stretch"]
    assert np.isfinite(row["x_err_cm_mean"]) and row["k"] in (1, 2)
    assert data["table"]["circle"]["none"]["k"] == 1
    assert data["wall_time_s"] > 0 and data["machine"]
    md = (tmp_path / "shapes.md").read_text()
    assert "| circle |" in md and "Noise test" in md and "Periodicity test" in md
    # Translators absent or untrained: skipped with a note, never given numbers.
    for method in ("ccgan", "wcgan"):
        if method not in results["methods_run"]:
            assert method not in data["table"]["circle"]
            assert any(method.upper() in n for n in data["notes"])
    if "ccgan" in results["methods_run"]:
        # Every method's commands are also scored through the CCGAN-GP checkpoint's F_c.
        for method in results["methods_run"]:
            fc = data["table"]["circle"][method]["fc_x_err_cm_mean"]
            assert np.isfinite(fc) and fc >= 0
        assert "forward model F_c" in md
    spread = data["periodicity"]["circle"]["stretch"]["spread_cm_max"]
    assert spread < 1e-9  # deterministic simulator and method: identical repetitions
    # Two trained WCGAN-GP models (identical copies here); repetitions use one model.
    assert data["table"]["circle"]["wcgan"]["n_seeds"] == 2
    assert data["periodicity"]["circle"]["wcgan"]["spread_cm_max"] < 1e-9
    video = tmp_path / "video_circle.mp4"
    assert video.exists() and video.stat().st_size > 0
    import imageio_ffmpeg

    frames = imageio_ffmpeg.read_frames(str(video))
    meta = next(frames)
    w, h = meta["size"]
    first = np.frombuffer(next(frames), np.uint8).reshape(h, w, 3)
    assert w == 3 * 128 and h == 96
    assert first.std() > 5.0  # not a blank frame
    assert (tmp_path / "shape_circle.png").exists()
    # Every long job shows a progress bar (on stderr).
    err = capsys.readouterr().err
    for bar in ("stretch k on the validation program", "D_c commands", "D_c rollouts"):
        assert bar in err
    assert "rendering videos" in err and "frame" in err


def test_translator_per_trained_seed(tmp_path):
    """translator_seed{s}.ckpt beside the checkpoint: one trained model per evaluation seed."""
    import shutil

    shipped = Path(__file__).resolve().parent.parent / "results" / "ccgan" / "translator.ckpt"
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(shipped, tmp_path / name)
    path = str(tmp_path / "translator.ckpt")
    two = pipeline.load_translator("ccgan", pipeline.EvalConfig(seeds=(0, 1), ccgan_path=path))[0]
    assert sorted(two.trained_seeds) == [0, 1] and two.takes_seed
    p_s = np.full((4, 3), 1.0)
    rest = np.tile([0.0, 0.0, -0.2, 0.0, 0.0, 1.0], (4, 1))  # tip (m), unit d3
    commands, k = two.translate(p_s, rest, seed=1)
    assert commands.shape == (4 * k, 3)
    # A seed without its own model: the single checkpoint serves every seed.
    three = pipeline.load_translator("ccgan", pipeline.EvalConfig(seeds=(0, 1, 2), ccgan_path=path))
    assert three[0].trained_seeds == {}


def test_default_translator_finds_its_trained_seeds(tmp_path, monkeypatch):
    """Without --ccgan-path the loader's default checkpoint is used, with its per-seed files."""
    import shutil

    shipped = Path(__file__).resolve().parent.parent / "results" / "ccgan" / "translator.ckpt"
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(shipped, tmp_path / name)
    monkeypatch.setenv("CCGAN_TRANSLATOR", str(tmp_path / "translator.ckpt"))
    tr, why = pipeline.load_translator("ccgan", pipeline.EvalConfig(seeds=(0, 1)))
    assert sorted(tr.trained_seeds) == [0, 1], why
    monkeypatch.delenv("CCGAN_TRANSLATOR")
    tr, _ = pipeline.load_translator("ccgan", pipeline.EvalConfig(seeds=(0, 1, 2)))
    committed = shipped.parent / "translator_seed2.ckpt"
    assert bool(tr.trained_seeds) == committed.exists()


def test_oracle_lowers_the_loss_and_batches_like_one_program(small_xml):
    """Adam through the MJX rollout: better than its start, in the valve range, and two programs
    optimised together get exactly the iterates each gets alone (Adam acts elementwise)."""
    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    k, n = 2, 4
    programs = [shapes.circle(3.0)[10 : 10 + n], shapes.kite(3.0)[10 : 10 + n]]
    targets = np.stack([arm_s.rollout(p, backend="c") for p in programs])
    inits = np.stack([pipeline.stretch(p, k) for p in programs])
    cfg = pipeline.OracleConfig(steps=4, learning_rate=0.3)
    both, info = pipeline.oracle_commands(arm_c, targets, inits, k, cfg)
    assert both.shape == (2, n * k, 3)
    lo, hi = arm_c.valve.p_min_bar, arm_c.valve.p_max_bar
    assert both.min() >= lo and both.max() <= hi
    history = np.asarray(info["loss_history"])
    assert history.shape == (4, 2) and np.isfinite(history).all()
    np.testing.assert_allclose(info["best_loss"], history.min(axis=0))
    assert (history.min(axis=0) < history[0]).all()  # it improved on the stretch program
    one, info_one = pipeline.oracle_commands(arm_c, targets[1], inits[1], k, cfg)
    np.testing.assert_allclose(one, both[1], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(info_one["loss_history"], history[:, 1], rtol=1e-5)
    # The tracking error of the returned commands in the C simulator is the optimised one.
    poses = pipeline.run_dc(arm_c, one, k, "c")
    x_err = metrics.position_error_cm(poses, targets[1])
    stretch_err = metrics.position_error_cm(pipeline.run_dc(arm_c, inits[1], k, "c"), targets[1])
    assert x_err.mean() < stretch_err.mean()
    with pytest.raises(ValueError, match="do not match"):
        pipeline.oracle_commands(arm_c, targets, inits[:, :-1], k, cfg)
    # Held like a translator's output: one command per source step, still better than stretch,
    # and no better than the free oracle, which can do everything the held one can.
    held, info_held = pipeline.oracle_commands(arm_c, targets, inits, k, cfg, held=[True, False])
    blocks = held[0].reshape(n, k, 3)
    np.testing.assert_allclose(blocks, np.broadcast_to(blocks[:, :1], blocks.shape))
    assert not np.allclose(both[0].reshape(n, k, 3), both[0].reshape(n, k, 3)[:, :1])
    np.testing.assert_allclose(held[1], both[1], rtol=1e-5, atol=1e-6)  # free one untouched
    h = np.asarray(info_held["loss_history"])[:, 0]
    assert h.min() < h[0]
    with pytest.raises(ValueError, match="constant over each step"):
        pipeline.oracle_commands(arm_c, targets, both, k, cfg, held=True)


def test_mpc_method_and_the_oracle_starting_from_it(small_xml, tmp_path, capsys):
    """The mpc row is the receding-horizon tracker's; the oracle starts from its commands."""
    cfg = pipeline.EvalConfig(
        shapes=("circle", "kite"),
        methods=("stretch", "mpc", "oracle"),
        seeds=(0,),
        duration_s=1.0,
        stretch_candidates=(4,),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        out_dir=str(tmp_path),
        xml=small_xml,
        oracle=pipeline.OracleConfig(steps=2, learning_rate=0.01, horizon_s=0.5),
    )
    data = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    arm_s, arm_c = pipeline.load_arms(cfg)
    programs = np.stack([shapes.circle(1.0), shapes.kite(1.0)])
    targets = arm_s.rollout(programs, backend="c")
    commands, _ = mpc.track(arm_c, targets, 4, programs)
    for i, shape in enumerate(cfg.shapes):
        row = data["table"][shape]
        err = metrics.tracking_errors(pipeline.run_dc(arm_c, commands[i], 4, "c"), targets[i])
        np.testing.assert_allclose(row["mpc"]["x_err_cm_mean"], err["x_err_cm_mean"], rtol=1e-9)
        assert (
            row["mpc"]["k"] == 4 and row["mpc"]["x_err_cm_mean"] < row["stretch"]["x_err_cm_mean"]
        )
        # The oracle's first iterate is the mpc's first 0.5 s, so its loss is theirs.
        head = pipeline.run_dc(arm_c, commands[i, :20], 4, "c")
        start_loss = float(tracking_loss(head, targets[i, :5], 10.0))
        np.testing.assert_allclose(row["oracle"]["oracle_loss_first"], start_loss, rtol=1e-3)
        assert row["oracle"]["oracle_loss_best"] <= row["oracle"]["oracle_loss_first"]
    assert "| shape | stretch | mpc | oracle |" in (tmp_path / "shapes.md").read_text()
    err = capsys.readouterr().err
    assert "oracle Adam steps" in err and "mpc" in err
    with pytest.raises(ValueError, match="oracle.init"):
        pipeline.OracleConfig(init="zeros")


def test_findings_count_shapes_and_ratios():
    """The findings section states counts and ratios computed from the table."""

    def row(x, ratio=None):
        r = {"x_err_cm_mean": x}
        if ratio is not None:
            r["x_ratio_to_oracle"] = ratio
        return r

    results = {
        "methods_run": ["none", "stretch", "ccgan", "oracle"],
        "table": {
            "circle": {"none": row(1.0), "stretch": row(0.2), "ccgan": row(0.1, 1.2)},
            "kite": {"none": row(0.5), "stretch": row(0.1), "ccgan": row(0.4, 2.0)},
        },
        "noise": {
            "circle": {"ccgan": {"0.1": row(0.2), "0.5": row(0.3)}},
            "kite": {"ccgan": {"0.1": row(0.5), "0.5": row(0.8)}},
        },
    }
    lines = pipeline.findings(results)
    assert (
        "- CCGAN-GP against untranslated: lower mean X_err on 2 of 2 shapes (circle, kite);"
        " X_err ratio CCGAN-GP / untranslated 0.10-0.80." in lines
    )
    assert (
        "- CCGAN-GP against stretch only: lower mean X_err on 1 of 2 shapes (circle);"
        " X_err ratio CCGAN-GP / stretch only 0.50-4.00." in lines
    )
    assert any("within 1.5x" in x and "1 of 2 shapes (circle)" in x for x in lines)
    # Largest level 0.5 (not the last key by string order): 0.3 / 0.1 = 3x and 0.8 / 0.4 = 2x.
    assert (
        "- Largest noise (std 0.5), CCGAN-GP: mean X_err 0.100-0.400 cm clean -> 0.300-0.800 cm"
        " (2.00-3.00x)." in lines
    )
    assert pipeline.findings({"methods_run": ["none"], "table": {"circle": {}}}) == []
