"""eval.shapes' ccgan_range: the conditioned translator over a range of media
(`ccgan.distill_range`, issue 51) scored in the run's own D_c at its rule's k. The label checks
(a range file only as ccgan_range, and no other file as it), the media it refuses before any
simulation, and one end-to-end run of the committed range translator in a medium of twice D_c's
drag, on the arm it was trained on (models/softarm.xml). CPU, MuJoCo C."""

import json

import numpy as np
import pytest

import mjx_arm  # noqa: F401  (before jax)
from ccgan.translator import TRANSLATORS_DIR, load_translator
from eval import methods, pipeline, shapes
from mjx_arm import constants, programs
from tracking import metrics
from tracking.held import rollout_grouped

#: The committed range translator (partially trained on one H200; translator.ckpt links seed 0).
RANGE_DIR = constants.ROOT / "studies" / "results" / "h200" / "media_range" / "range"
RANGE_FILE = RANGE_DIR / "translator.ckpt"
#: A translator of one pair, labelled "distill" for D_c.
DISTILLED_FILE = TRANSLATORS_DIR / "ccgan_sim" / "translator.ckpt"


@pytest.fixture(scope="module")
def range_translator():
    return load_translator(RANGE_FILE)


def _domain_file(path, **fields) -> str:
    path.write_text(json.dumps({"domain": fields}))
    return str(path)


def test_only_a_range_file_loads_as_ccgan_range_and_never_as_another_method():
    """A translator of one pair given as ccgan_range, and a range file given as the distilled
    translator (or as CCGAN-GP), are refused by their labels, naming both methods and the
    flag; the range file loads as ccgan_range whatever the run's target (its label is
    "media_range"), with its seeds beside it."""
    cfg = pipeline.EvalConfig(ccgan_range_path=str(DISTILLED_FILE), seeds=(0,))
    with pytest.raises(methods.TranslatorError) as exc:
        methods.load_translator("ccgan_range", cfg)
    message = str(exc.value)
    assert "expects method 'distill_range'" in message and "has 'distill'" in message
    assert "--range-path" in message
    for method in ("ccgan_sim", "ccgan"):
        cfg = pipeline.EvalConfig(**{f"{method}_path": str(RANGE_FILE)}, seeds=(0,))
        with pytest.raises(methods.TranslatorError) as exc:
            methods.load_translator(method, cfg)
        assert "the file has 'distill_range'" in str(exc.value)
        assert methods.PATH_FLAGS[method] in str(exc.value)
    cfg = pipeline.EvalConfig(ccgan_range_path=str(RANGE_FILE), seeds=(0, 1, 2))
    tr, why = methods.load_translator("ccgan_range", cfg)
    assert sorted(tr.trained_seeds) == [0, 1, 2] and "trained seeds" in why
    assert [f.name for f in tr.files[1:]] == [f"translator_seed{s}.ckpt" for s in (0, 1, 2)]


@pytest.mark.parametrize(
    ("target", "medium", "k"),
    # D_c (viscosity_scale None: the model's own) is r = 10; the aged arm is D_c's medium at 0.7.
    [("constrained", (10.0, 1.0), 15), ("aged", (10.0, 0.7), 25)],
)
def test_a_named_target_is_its_built_in_domain_read_as_r_and_s(target, medium, k):
    cfg = pipeline.EvalConfig(ccgan_range_path=str(RANGE_FILE), seeds=(0,), target_domain=target)
    tr, _ = methods.load_translator("ccgan_range", cfg)
    assert tr.target == mjx_arm.domains.resolve(target)
    record = tr.labels[0]["medium"]
    assert (record["drag_ratio"], record["stiffness_scale"]) == pytest.approx(medium, abs=1e-12)
    assert record["k"] == k and record["role"] == "held out"
    assert tr.labels[0]["method"] == "distill_range"


def test_a_medium_outside_the_range_is_refused_before_any_work(tmp_path, range_translator):
    """Sixty times D_c's viscosity (r = 600) and a stiffness below 0.6: refused when the
    translator loads, naming the method, the medium and the range; no output folder."""
    scale = range_translator.media.constrained_viscosity_scale
    cases = (
        ({"viscosity_scale": 60 * scale}, "drag ratio r = 600", "drag ratio 600"),
        ({"stiffness_scale": 0.5, "viscosity_scale": scale}, "stiffness_scale 0.5", "0.5 is"),
    )
    for i, (fields, medium, why) in enumerate(cases):
        path = _domain_file(tmp_path / f"m{i}.json", **fields)
        cfg = pipeline.EvalConfig(
            shapes=("circle",),
            methods=("none", "ccgan_range"),
            seeds=(0,),
            duration_s=1.0,
            target_domain_file=path,
            ccgan_range_path=str(RANGE_FILE),
            plots=False,
            out_dir=str(tmp_path / "out"),
        )
        with pytest.raises(methods.TranslatorError) as exc:
            pipeline.evaluate(cfg, command="test", log=lambda *_: None)
        message = str(exc.value)
        assert message.startswith("ccgan_range (--range-path)") and medium in message, message
        assert "drag ratio r [2.0, 30.0], stiffness scale s [0.6, 1.0]" in message
        assert why in message and "outside the range" in message
        assert not (tmp_path / "out").exists()


def test_the_range_translator_is_refused_on_another_arm(small_xml):
    """Its files record models/softarm.xml: the 3-segment test arm stops the run."""
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "ccgan_range"),
        seeds=(0,),
        duration_s=1.0,
        xml=small_xml,
        ccgan_range_path=str(RANGE_FILE),
        plots=False,
    )
    with pytest.raises(methods.TranslatorError, match="ccgan_range: trained on the arm"):
        pipeline.evaluate(cfg, command="test", log=lambda *_: None)


def test_the_flag_and_the_absent_default(tmp_path):
    cfg = shapes.parse_args(
        ["--methods", "none", "ccgan_range", "--range-path", str(RANGE_FILE)]
        + ["--out", str(tmp_path / "o")]
    )
    assert cfg.ccgan_range_path == str(RANGE_FILE) and cfg.methods == ("none", "ccgan_range")
    assert "ccgan_range" not in methods.DEFAULT_METHODS
    tr, why = methods.load_translator("ccgan_range", pipeline.EvalConfig())
    assert tr is None and str(methods.RANGE_DEFAULT_PATH) in why and "--range-path" in why


def test_scored_in_a_domain_file_at_the_rules_k(tmp_path, range_translator):
    """Twice D_c's viscosity (r = 20, s = 1, a medium it was not taught on): the ccgan_range
    row holds the rule's k for (20, 1), shapes.json's labels record (r, s) and k, and its
    X_err is that of `Translator.translate(p, x, target=(20, 1))` run in the file's medium."""
    scale = range_translator.media.constrained_viscosity_scale
    medium = _domain_file(tmp_path / "r20.json", viscosity_scale=2 * scale)
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "stretch", "ccgan_range"),
        seeds=(0,),
        duration_s=2.0,
        hold_factors=(1, 5),
        validation_duration_s=1.0,
        robustness=False,
        backend="c",
        plots=False,
        target_domain_file=medium,
        ccgan_range_path=str(RANGE_FILE),
        out_dir=str(tmp_path / "out"),
    )
    results = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    k_rule = range_translator.target_condition((20.0, 1.0))[1]
    assert k_rule == 30  # the grid's nearest to 0.526 x the fitted 65.4 s
    row = results["table"]["circle"]["ccgan_range"]
    assert results["methods_run"] == ["none", "stretch", "ccgan_range"] and row["k"] == k_rule
    record = results["translator_labels"]["ccgan_range"][0]["medium"]
    assert record["drag_ratio"] == pytest.approx(20.0, rel=1e-12) and record["k"] == k_rule
    assert record["stiffness_scale"] == 1.0 and record["role"] == "other"
    assert any("r = 20, stiffness s = 1" in n and "k = 30" in n for n in results["notes"])
    assert "drag ratio r = 20" in (tmp_path / "out" / "shapes.md").read_text()

    # The same commands as the translator's own for (20, 1), and the row's X_err is theirs.
    arm_s, arm_c = pipeline.load_arms(cfg)
    p_s = programs.SHAPES["circle"](cfg.duration_s)
    target = rollout_grouped(arm_s, [(p_s, 1)], "c")[0]
    tr, _ = methods.load_translator("ccgan_range", cfg)
    commands, k = methods.method_commands("ccgan_range", p_s, target, 0, {"ccgan_range": tr}, 1)
    expected, k_expected = range_translator.translate(p_s, target, target=(20.0, 1.0))
    assert k == k_expected == k_rule and commands.shape == (p_s.shape[0] * k, 3)
    np.testing.assert_array_equal(commands, expected)
    poses = rollout_grouped(arm_c, [(commands, k)], "c")[0]
    x_err = metrics.tracking_errors(poses[None], target)["x_err_cm_mean"]
    assert row["x_err_cm_mean"] == pytest.approx(x_err, rel=1e-9)
