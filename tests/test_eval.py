"""Tests of eval/: noise, replay, translators, the mpc and oracle rows, and tiny end-to-end runs
(3-segment arm, CPU). The programs, metrics and trackers have their own tests (test_programs,
test_tracking, test_tracking_mpc)."""

import dataclasses
import json

import numpy as np
import pytest

import mjx_arm  # (before jax)
from ccgan.translator import SOLID_TRANSLATORS_DIR
from eval import methods, pipeline, render, report, simulate
from mjx_arm import programs
from tracking import held, metrics, mpc
from tracking.metrics import tracking_loss
from tracking.oracle import OracleConfig

#: The solid-disc arm's committed CCGAN-GP translator (a link to its first seed's file). Its
#: files record no arm, so it runs on the tests' 3-segment arms; the I-Support arm's record theirs.
SHIPPED_TRANSLATOR = SOLID_TRANSLATORS_DIR / "ccgan" / "translator.ckpt"


@pytest.fixture(scope="module")
def small_xml():
    return mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))


def test_noise_is_clipped_and_zero_mean():
    p = np.full((4000, 3), 1.75)
    noisy = simulate.add_noise(p, 0.1, seed=0)
    assert noisy.min() >= 0 and noisy.max() <= 3.5
    assert abs(noisy.mean() / 3.5 - 0.5) < 0.01
    assert abs((noisy / 3.5).std() - 0.1) < 0.01
    np.testing.assert_array_equal(noisy, simulate.add_noise(p, 0.1, seed=0))


def test_replay_matches_rollout(small_xml):
    arm = mjx_arm.load(xml=small_xml, domain="source")
    p = programs.circle(2.0)
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
    shipped = SHIPPED_TRANSLATOR
    (tmp_path / "wcgan").mkdir()
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(shipped, tmp_path / "wcgan" / name)
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "stretch", "ccgan", "wcgan"),
        seeds=(0, 1),
        ccgan_path=str(shipped),
        wcgan_path=str(tmp_path / "wcgan" / "translator.ckpt"),
        trust_unlabelled_translators=True,
        duration_s=2.0,
        hold_factors=(1, 2),
        validation_duration_s=1.0,
        noise_stds=(0.1,),
        n_repeats=2,
        robust_methods=("stretch", "ccgan", "wcgan"),
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
    # D_s beside the D_c panels: the best translator run, stretch only, untranslated.
    shown = render.video_plan(
        {"pressures_s": np.zeros((20, 3)), "commands": dict.fromkeys(results["methods_run"])}, cfg
    )[1]
    assert shown[1:] == ["stretch", "none"] and shown[0] in ("ccgan", "wcgan")
    assert w == (1 + len(shown)) * 128 and h == 96
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

    shipped = SHIPPED_TRANSLATOR
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(shipped, tmp_path / name)
    path = str(tmp_path / "translator.ckpt")
    trust = {"trust_unlabelled_translators": True}  # the solid-disc arm's files have no labels
    two = methods.load_translator(
        "ccgan", pipeline.EvalConfig(seeds=(0, 1), ccgan_path=path, **trust)
    )[0]
    assert sorted(two.trained_seeds) == [0, 1] and two.takes_seed
    p_s = np.full((4, 3), 1.0)
    rest = np.tile([0.0, 0.0, -0.2, 0.0, 0.0, 1.0], (4, 1))  # tip (m), unit d3
    commands, k = two.translate(p_s, rest, seed=1)
    assert commands.shape == (4 * k, 3)
    # A seed without its own model: the single checkpoint serves every seed.
    three = methods.load_translator(
        "ccgan", pipeline.EvalConfig(seeds=(0, 1, 2), ccgan_path=path, **trust)
    )
    assert three[0].trained_seeds == {}


def test_default_translator_finds_its_trained_seeds(tmp_path, monkeypatch):
    """Without --ccgan-path the loader's default checkpoint is used, with its per-seed files."""
    import shutil

    shipped = SHIPPED_TRANSLATOR
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(shipped, tmp_path / name)
    monkeypatch.setenv("CCGAN_TRANSLATOR", str(tmp_path / "translator.ckpt"))
    trust = {"trust_unlabelled_translators": True}  # the solid-disc arm's files have no labels
    tr, why = methods.load_translator("ccgan", pipeline.EvalConfig(seeds=(0, 1), **trust))
    assert sorted(tr.trained_seeds) == [0, 1], why
    # Without the variable, DEFAULT_PATH: its per-seed files are used only when there is one
    # for every evaluation seed (here seed 2's is missing, then added).
    import ccgan.translator

    monkeypatch.delenv("CCGAN_TRANSLATOR")
    monkeypatch.setattr(ccgan.translator, "DEFAULT_PATH", tmp_path / "translator.ckpt")
    three = pipeline.EvalConfig(seeds=(0, 1, 2), **trust)
    tr, why = methods.load_translator("ccgan", three)
    assert tr.trained_seeds == {} and why == "loaded"
    shutil.copy(shipped, tmp_path / "translator_seed2.ckpt")
    tr, why = methods.load_translator("ccgan", three)
    assert sorted(tr.trained_seeds) == [0, 1, 2] and why == "loaded, trained seeds [0, 1, 2]"


@pytest.mark.slow
def test_mpc_method_and_the_oracle_starting_from_it(small_xml, tmp_path, capsys):
    """The mpc row is the receding-horizon tracker's; the oracle starts from its commands."""
    cfg = pipeline.EvalConfig(
        shapes=("circle", "kite"),
        methods=("stretch", "mpc", "oracle"),
        seeds=(0,),
        duration_s=1.0,
        hold_factors=(4,),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        out_dir=str(tmp_path),
        xml=small_xml,
        oracle=OracleConfig(steps=2, learning_rate=0.01, horizon_s=0.5),
    )
    data = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    arm_s, arm_c = pipeline.load_arms(cfg)
    sources = np.stack([programs.circle(1.0), programs.kite(1.0)])
    targets = arm_s.rollout(sources, backend="c")
    commands, _ = mpc.track(arm_c, targets, 4, sources)
    for i, shape in enumerate(cfg.shapes):
        row = data["table"][shape]
        err = metrics.tracking_errors(held.run_dc(arm_c, commands[i], 4, "c"), targets[i])
        np.testing.assert_allclose(row["mpc"]["x_err_cm_mean"], err["x_err_cm_mean"], rtol=1e-9)
        assert (
            row["mpc"]["k"] == 4 and row["mpc"]["x_err_cm_mean"] < row["stretch"]["x_err_cm_mean"]
        )
        # The oracle's first iterate is the mpc's first 0.5 s, so its loss is theirs.
        head = held.run_dc(arm_c, commands[i, :20], 4, "c")
        start_loss = float(tracking_loss(head, targets[i, :5], 10.0))
        np.testing.assert_allclose(row["oracle"]["oracle_loss_first"], start_loss, rtol=1e-3)
        assert row["oracle"]["oracle_loss_best"] <= row["oracle"]["oracle_loss_first"]
    assert "| shape | stretch | mpc | oracle |" in (tmp_path / "shapes.md").read_text()
    err = capsys.readouterr().err
    assert "oracle Adam steps" in err and "mpc" in err
    # The run keeps the tracker's commands in its folder; the same run again reads them back.
    kept = {simulate.MPC_RESULT, simulate.ORACLE_START, simulate.ORACLE_PROGRESS}
    assert kept <= {p.name for p in tmp_path.iterdir()}
    logs = []
    again = pipeline.evaluate(cfg, command="test", log=logs.append)
    assert any(f"read from {simulate.MPC_RESULT}" in str(line) for line in logs)
    assert again["table"]["kite"]["mpc"] == data["table"]["kite"]["mpc"]
    with pytest.raises(ValueError, match="oracle.init"):
        OracleConfig(init="zeros")


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
    lines = report.findings(results)
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
    assert report.findings({"methods_run": ["none"], "table": {"circle": {}}}) == []
