"""`python -m eval.shapes --simulator rod`: the five-shape evaluation scored in the reference rod.

A tiny run (one 1 s shape, k in (1, 2), a 0.5 s validation program) scores what `load_rod`
rollouts give directly; the oracle, --render and --backend mjx are usage errors before any work;
translators of the chain and of the rod's own data are scored, any other arm's refused.
"""

import hashlib
import json

import numpy as np
import pytest

import mjx_arm  # (before jax)
from eval import methods, pipeline, report, rod, shapes
from mjx_arm import constants, programs
from tracking import held, metrics
from tracking.config import ConfigError

#: The solid-disc arm's CCGAN-GP (k = 10): relabelled here for each arm.
SHIPPED = constants.ROOT / "results" / "solid" / "translators" / "ccgan" / "translator.ckpt"
CHAIN_HASH = hashlib.sha256(constants.TRANSLATOR_MODEL_PATH.read_text().encode()).hexdigest()[:16]


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    """Runs the test in an empty folder, with no translator chosen through the environment."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    return tmp_path


def _tiny(out, **kw) -> pipeline.EvalConfig:
    settings = dict(
        shapes=("circle",),
        methods=("none", "stretch"),
        seeds=(0,),
        duration_s=1.0,
        hold_factors=(1, 2),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        simulator="rod",
        out_dir=str(out),
    )
    return pipeline.EvalConfig(**settings | kw)


def test_a_tiny_rod_evaluation_scores_what_the_rod_gives(in_tmp, capsys, monkeypatch):
    data = pipeline.evaluate(_tiny(in_tmp / "out"), command="test", log=print)
    rod_s, rod_c = mjx_arm.load_rod("source"), mjx_arm.load_rod("constrained")
    # Stretch only's k: the validation program in the rod.
    p_val = programs.validation_program(0.5)
    val_target = rod_s.rollout(p_val)
    for k in (1, 2):
        poses = held.every_kth(rod_c.rollout(held.stretch(p_val, k)), k)
        want = metrics.position_error_cm(poses, val_target).mean()
        assert data["stretch_validation_x_err_cm"][str(k)] == pytest.approx(want, rel=1e-9)
    k = data["stretch_k"]
    # The table: the rod's D_s path as target, every method's commands in the D_c rod.
    p_s = programs.circle(1.0)
    target = rod_s.rollout(p_s)
    row = data["table"]["circle"]
    for method, commands, hold in (("none", p_s, 1), ("stretch", held.stretch(p_s, k), k)):
        poses = held.every_kth(rod_c.rollout(commands), hold)
        errors = metrics.tracking_errors(poses[None], target)
        assert row[method]["k"] == hold
        assert row[method]["x_err_cm_mean"] == pytest.approx(errors["x_err_cm_mean"], rel=1e-9)
        assert row[method]["phi_err_rad_mean"] == pytest.approx(
            errors["phi_err_rad_mean"], rel=1e-9
        )
    # Not the chain's numbers: the same untranslated program in the chain scores otherwise.
    chain_s, chain_c = pipeline.load_arms(pipeline.EvalConfig())
    chain = metrics.tracking_errors(
        chain_c.rollout(p_s, backend="c")[None], chain_s.rollout(p_s, backend="c")
    )
    assert abs(chain["x_err_cm_mean"] - row["none"]["x_err_cm_mean"]) > 1e-3
    # The files say which simulator scored the table.
    assert data["simulator"] == "rod" and data["backend"] == "rod"
    assert data["model_hash"] == data["rod"]["model_hash"] == rod_c.model_hash
    assert data["rod"]["chain_model_hash"] == CHAIN_HASH
    written = json.loads((in_tmp / "out" / "shapes.json").read_text())
    assert written["simulator"] == "rod"
    md = (in_tmp / "out" / "shapes.md").read_text()
    assert "- scored in: the reference rod (paper's law), float64" in md
    assert md == report.markdown_report(written)
    assert "D_s targets (rod)" in capsys.readouterr().err
    # A GPU's path (padded batches, each announced) scores the same.
    monkeypatch.setattr(mjx_arm.RodArm, "call_size", lambda self: 512)
    again = pipeline.evaluate(_tiny(in_tmp / "padded"), command="test", log=print)
    assert again["stretch_k"] == k
    for method in ("none", "stretch"):
        assert again["table"]["circle"][method]["x_err_cm_mean"] == pytest.approx(
            row[method]["x_err_cm_mean"], rel=1e-9
        )
    err = capsys.readouterr().err
    assert "stretch k on the validation program: the rod runs 2 trajectories together" in err
    assert "D_c rollouts (2 shape x method, 0 noise + periodicity): the rod runs 2" in err


def test_the_chains_report_names_the_chain_and_older_files_render_as_before():
    results = json.loads((constants.ROOT / "results" / "shapes.json").read_text())
    assert "simulator" not in results and "scored in" not in report.markdown_report(results)
    chain = report.markdown_report(results | {"simulator": "chain"})
    assert f"- scored in: {rod.SCORED_IN['chain']}" in chain and "reference rod" not in chain


@pytest.mark.parametrize(
    "extra, reason",
    [
        (["--methods", "none", "oracle"], "the oracle optimises through MJX of the chain"),
        (["--render"], "--render is refused"),
        (["--backend", "mjx"], "--backend mjx is refused"),
    ],
)
def test_what_the_rod_cannot_do_is_a_usage_error_before_any_work(in_tmp, capsys, extra, reason):
    argv = ["--simulator", "rod", "--shapes", "circle", "--out", str(in_tmp / "out"), *extra]
    with pytest.raises(SystemExit) as exc:
        shapes.parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1]  # one line naming the flag and why
    assert last.startswith("python -m eval.shapes: error: --simulator rod: ") and reason in last
    assert not (in_tmp / "out").exists()


def test_the_rod_setting_is_checked_in_the_config_and_its_default_leaves_out_the_oracle(
    in_tmp, monkeypatch, capsys
):
    with pytest.raises(ConfigError) as exc:
        pipeline.EvalConfig(simulator="rod", methods=("none", "oracle"))
    assert exc.value.field == "simulator"
    with pytest.raises(ConfigError, match="must be one of"):
        pipeline.EvalConfig(simulator="pyelastica")
    # The GPU's default methods include the oracle; with the rod it is left out, with a note.
    monkeypatch.setattr(shapes, "default_methods", lambda: methods.DEFAULT_METHODS)
    cfg = shapes.parse_args(["--simulator", "rod", "--out", str(in_tmp / "o")])
    assert cfg.simulator == "rod" and "oracle" not in cfg.methods and "wcgan" in cfg.methods
    assert "--simulator rod leaves the oracle out" in capsys.readouterr().out
    assert not pipeline.is_main_job(cfg)
    assert shapes.parse_args(["--out", str(in_tmp / "o")]).simulator == "chain"


def _labelled(tmp_path, name, method, model_hash):
    """The shipped translator labelled as made by `method` for D_c on the arm `model_hash`."""
    from ccgan import checkpoint

    tree, meta = checkpoint.load(SHIPPED)
    labels = {
        "method": method,
        "source_domain": "source",
        "target_domain": "constrained",
        "model_hash": model_hash,
    }
    return checkpoint.save(tmp_path / name, tree, meta | labels)


def test_translators_of_the_chain_and_of_the_rod_are_scored_others_refused(in_tmp):
    rod_hash = mjx_arm.load_rod("constrained").model_hash
    chain = _labelled(in_tmp, "chain.ckpt", "ccgan", CHAIN_HASH)
    own = _labelled(in_tmp, "rod.ckpt", "distill", rod_hash)
    other = _labelled(in_tmp, "other.ckpt", "ccgan", "0123456789abcdef")
    # Another arm's translator: refused in rod mode before any work or folder.
    with pytest.raises(methods.TranslatorError, match="0123456789abcdef") as exc:
        pipeline.evaluate(
            _tiny(in_tmp / "refused", methods=("ccgan",), ccgan_path=str(other)),
            log=lambda *_: None,
        )
    assert CHAIN_HASH in str(exc.value) and rod_hash in str(exc.value)
    assert not (in_tmp / "refused").exists()
    # The rod's translator in chain mode: refused, with a hint at the rod.
    with pytest.raises(methods.TranslatorError, match="--simulator rod"):
        pipeline.evaluate(
            pipeline.EvalConfig(**_chain_settings(in_tmp, ccgan_sim_path=str(own))),
            log=lambda *_: None,
        )
    assert not (in_tmp / "chain").exists()
    # Both accepted in rod mode; the report says which arm each was trained on.
    cfg = _tiny(
        in_tmp / "out",
        methods=("ccgan", "ccgan_sim"),
        ccgan_path=str(chain),
        ccgan_sim_path=str(own),
    )
    data = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    assert data["methods_run"] == ["ccgan", "ccgan_sim"]
    assert data["rod"]["translators_trained_on"] == {
        "ccgan": rod.CHAIN_TRAINED,
        "ccgan_sim": rod.ROD_TRAINED,
    }
    note = data["model"]["note"]
    assert f"CCGAN-GP from {chain} ({rod.CHAIN_TRAINED})" in note
    assert f"distilled from {own} ({rod.ROD_TRAINED})" in note
    # The same network gives the same commands; both ran in the rod (one rollout, shared).
    rows = data["table"]["circle"]
    assert rows["ccgan"]["k"] == 10
    assert rows["ccgan"]["x_err_cm_mean"] == rows["ccgan_sim"]["x_err_cm_mean"]
    assert np.isfinite(rows["ccgan"]["x_err_cm_mean"])


def _chain_settings(tmp_path, **kw) -> dict:
    """A tiny chain-mode run's settings (its translator check stops it before any work)."""
    return dict(
        shapes=("circle",),
        methods=("ccgan_sim",),
        seeds=(0,),
        duration_s=1.0,
        hold_factors=(1,),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        out_dir=str(tmp_path / "chain"),
        **kw,
    )
