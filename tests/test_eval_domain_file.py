"""eval.shapes scored in a medium given by a Domain file (EvalConfig.target_domain_file,
--target-domain-file): the config's refusals, the translator label checks, a tiny end-to-end
run on the 3-segment arm against the built-in "constrained" medium, and the oracle's kept
progress keyed on the medium."""

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest

import mjx_arm  # noqa: F401  (before jax)
from ccgan import checkpoint
from ccgan.translator import SOLID_TRANSLATORS_DIR
from eval import methods, pipeline, report, shapes
from mjx_arm import domains
from tracking import oracle
from tracking.config import ConfigError


def _domain_file(path, **fields):
    """Writes a plain {"domain": {...}} file; returns its path as a str."""
    path.write_text(json.dumps({"domain": fields}))
    return str(path)


# ------------------------------------------------------------------ the config's refusals


@pytest.mark.parametrize(
    ("content", "given", "words"),
    [
        (None, {}, "no such file"),
        ("{not json", {}, "is not JSON"),
        ('{"domain": {"viscosity_scale": 2.0, "drag": 3}}', {}, "unknown Domain fields ['drag']"),
        ('{"domain": {"viscosity_scale": -1}}', {}, "finite and > 0"),
        ('{"domain": {"viscosity_scale": 2.0}}', {"target_domain": "aged"}, "one or the other"),
        (
            '{"domain": {"viscosity_scale": 2.0}}',
            {"simulator": "rod", "methods": ("none",)},
            "only its own",
        ),
    ],
)
def test_a_bad_domain_file_or_setting_is_refused_naming_the_field(tmp_path, content, given, words):
    """Refused when the config is made (no arm loaded, no simulation): a ValueError
    (`ConfigError`) whose field is target_domain_file."""
    path = tmp_path / "d.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(ConfigError) as exc:
        pipeline.EvalConfig(target_domain_file=str(path), **given)
    assert isinstance(exc.value, ValueError) and exc.value.field == "target_domain_file"
    assert words in str(exc.value)


def test_the_flag_sets_the_field_and_its_refusal_names_the_flag(tmp_path, capsys):
    good = _domain_file(tmp_path / "d.json", viscosity_scale=40.0)
    cfg = shapes.parse_args(["--target-domain-file", good, "--out", str(tmp_path / "o")])
    assert cfg.target_domain_file == good and cfg.target_domain == "constrained"
    assert not pipeline.is_main_job(dataclasses.replace(cfg, out_dir=None))
    with pytest.raises(SystemExit):
        shapes.parse_args(["--target-domain-file", str(tmp_path / "none.json")])
    assert "--target-domain-file is unusable" in capsys.readouterr().err


# ------------------------------------------------------------------ translators


@pytest.fixture()
def identified_files(small_xml, tmp_path):
    """A Domain file and translators (the solid-disc arm's CCGAN-GP relabelled as distilled on
    the 3-segment arm): labelled "identified" and taught on that file's fields ("same"), on
    other fields ("other"), with no taught record ("bare"), and labelled "constrained"."""
    target = _domain_file(tmp_path / "target.json", viscosity_scale=40.0, stiffness_scale=0.8)
    same = domains.read_domain_file(
        _domain_file(tmp_path / "same.json", stiffness_scale=0.8, viscosity_scale=40.0)
    )
    tree, meta = checkpoint.load(SOLID_TRANSLATORS_DIR / "ccgan" / "translator.ckpt")
    arm_hash = mjx_arm.load(xml=small_xml, domain="source").model_hash
    labels = {"method": "distill", "source_domain": "source", "model_hash": arm_hash, "k": 2}
    stage = {"method": "distill", "model_hash": arm_hash}
    other = same.record() | {"domain": dataclasses.asdict(same.domain) | {"stiffness_scale": 0.7}}
    files = {}
    for name, target_label, taught in (
        ("same", "identified", same.record()),
        ("other", "identified", other),
        ("bare", "identified", None),
        ("constrained", "constrained", same.record()),
    ):
        finetune = stage | ({"taught_domain": taught} if taught else {})
        content = meta | labels | {"target_domain": target_label, "finetune": finetune}
        files[name] = str(checkpoint.save(tmp_path / f"{name}.ckpt", tree, content))
    return target, files


def test_identified_translators_load_only_for_the_same_domain_fields(small_xml, identified_files):
    """A file labelled "identified" loads when the Domain file it was taught on holds the
    eval's file's fields (another path, another key order); one taught on other fields, one
    that records no Domain file (given as the distilled one), and one labelled for a built-in
    target are refused."""
    target, files = identified_files
    base = {"xml": small_xml, "seeds": (0,), "target_domain_file": target}

    def load(name, method="ccgan_ident"):
        cfg = pipeline.EvalConfig(**{f"{method}_path": files[name]}, **base)
        return methods.load_translator(method, cfg)

    tr, why = load("same")
    assert tr is not None and why == "loaded"
    with pytest.raises(methods.TranslatorError, match=r"stiffness_scale 0\.7 \(here 0\.8\)"):
        load("other")
    with pytest.raises(methods.TranslatorError, match="records no Domain file"):
        load("bare", "ccgan_sim")  # (as ccgan_ident: refused as taught in its target)
    with pytest.raises(methods.TranslatorError) as exc:
        load("constrained")
    assert "expects target_domain 'identified'" in str(exc.value)
    assert f"--target-domain-file {target}" in str(exc.value)
    # Without a Domain file the "identified" one is refused for the built-in target.
    builtin = pipeline.EvalConfig(ccgan_ident_path=files["same"], xml=small_xml, seeds=(0,))
    with pytest.raises(methods.TranslatorError, match="expects target_domain 'constrained'"):
        methods.load_translator("ccgan_ident", builtin)


def test_a_taught_medium_within_the_tolerance_is_scored_in_the_true_one(
    small_xml, identified_files
):
    """`taught_medium_rtol`: a translator taught on an identified medium is scored in the true
    one when each field is within the relative tolerance ("other" is taught at stiffness 0.7
    against the file's 0.8: 12.5%); beyond it, and with no tolerance, it is refused."""
    target, files = identified_files

    def load(rtol):
        cfg = pipeline.EvalConfig(
            ccgan_ident_path=files["other"], xml=small_xml, seeds=(0,), target_domain_file=target,
            taught_medium_rtol=rtol,
        )  # fmt: skip
        return methods.load_translator("ccgan_ident", cfg)

    tr, why = load(0.2)
    assert tr is not None and tr.labels[0]["taught_domain"]["domain"]["stiffness_scale"] == 0.7
    with pytest.raises(methods.TranslatorError, match="more than --taught-medium-rtol 0.1"):
        load(0.1)
    with pytest.raises(methods.TranslatorError, match=r"stiffness_scale 0\.7 \(here 0\.8\)"):
        load(0.0)
    with pytest.raises(ConfigError, match="taught_medium_rtol"):
        load(-0.1)


# ------------------------------------------------------------------ scored in the file's medium


def test_a_domain_file_of_the_constrained_medium_scores_as_constrained(small_xml, tmp_path):
    """A Domain file whose viscosity_scale is the model's own constrained scale gives the same
    untranslated and stretch-only X_err (and k) as target_domain "constrained"; twice that
    viscosity gives others. shapes.json and shapes.md record the file."""
    scale = domains.model_viscosity_scale(mjx_arm.load(xml=small_xml, domain="source").mj_model)
    same = _domain_file(tmp_path / "same.json", viscosity_scale=scale)
    double = _domain_file(tmp_path / "double.json", viscosity_scale=2 * scale)
    base = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "stretch"),
        seeds=(0,),
        duration_s=2.0,
        hold_factors=(1, 3),
        validation_duration_s=1.0,
        robustness=False,
        plots=False,
        xml=small_xml,
    )

    def run(name, **given):
        cfg = dataclasses.replace(base, out_dir=str(tmp_path / name), **given)
        return pipeline.evaluate(cfg, command="test", log=lambda *_: None)

    named = run("named")
    from_file = run("same", target_domain_file=same)
    doubled = run("double", target_domain_file=double)
    assert from_file["stretch_k"] == named["stretch_k"]
    for method in ("none", "stretch"):
        want = named["table"]["circle"][method]["x_err_cm_mean"]
        got = from_file["table"]["circle"][method]["x_err_cm_mean"]
        assert got == pytest.approx(want, rel=1e-9, abs=0)
        other = doubled["table"]["circle"][method]["x_err_cm_mean"]
        assert other != pytest.approx(want, rel=1e-6)
    record = json.loads((tmp_path / "double" / "shapes.json").read_text())["target_domain_file"]
    assert record["path"] == double and len(record["sha256"]) == 64
    assert record["domain"]["viscosity_scale"] == 2 * scale
    assert record["domain"]["name"] == domains.IDENTIFIED
    assert record["values"]["viscosity_scale"] == pytest.approx(2 * scale)
    md = (tmp_path / "double" / "shapes.md").read_text()
    assert "domains: source -> identified (Domain file)" in md
    assert f"- D_c read from the Domain file `{double}` (sha256 {record['sha256'][:16]})" in md
    assert "domains: source -> constrained" in (tmp_path / "named" / "shapes.md").read_text()
    assert "target_domain_file" not in named
    assert report.target_name(named) == "constrained"


def test_the_oracles_kept_progress_is_keyed_on_a_file_domain_only(small_xml, tmp_path):
    """The oracle's progress file (oracle_progress.npz) of one Domain file's medium is never
    read in another's (both share the MJCF's hash), while a built-in medium's key is what it
    was (the arm's hash alone), so progress kept before stays valid."""

    def key(arm):
        zeros = np.zeros((1, 4, 3))
        return oracle._fingerprint(arm, zeros, zeros, np.ones(1, bool), 2, oracle.OracleConfig())

    arms = [
        mjx_arm.load(xml=small_xml, domain=domains.read_domain_file(f).domain)
        for f in (
            _domain_file(tmp_path / "a.json", viscosity_scale=30.0),
            _domain_file(tmp_path / "b.json", viscosity_scale=40.0),
        )
    ]
    assert key(arms[0]) != key(arms[1])
    constrained = mjx_arm.load(xml=small_xml, domain="constrained")
    assert key(constrained) == key(SimpleNamespace(model_hash=constrained.model_hash))
