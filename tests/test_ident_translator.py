"""A translator taught on an identified arm (issue 50, item 2): a Domain read from a file
(`mjx_arm.domains.read_domain_file`), the distillation taught on it with k chosen there
(`ccgan.distill --teach-domain --k-candidates`), its score in the true target (`eval.shapes`'s
ccgan_ident) and the chain's stages. CPU, tiny arms and programs."""

import dataclasses
import hashlib
import json
import shlex

import numpy as np
import pytest

import mjx_arm  # (before jax: sets the XLA CPU flag)
from ccgan import checkpoint, distill
from ccgan.translator import SOLID_TRANSLATORS_DIR, taught_domain, translator_path
from eval import methods, pipeline
from experiments import paper, report
from experiments.chain import Chain, load_config
from mjx_arm import domains, programs
from tracking import held, metrics
from tracking.metrics import position_error_cm

#: The committed identification of the chain's D_c arm (search and gradient on the same data).
COMMITTED_IDENTIFY = mjx_arm.constants.ROOT / "studies/results/cpu/identify/constrained"


def _identify_json(path, results: dict):
    """An identify.json as `mjx_arm.identify` writes it, with these {method: result} entries."""
    path.write_text(json.dumps({"command": "x", "data": {}, "truth": None, "results": results}))
    return path


def _result(viscosity: float, stiffness: float, val_rms_cm: float, method: str) -> dict:
    fields = dataclasses.asdict(
        mjx_arm.Domain(
            name=f"identified ({method})", viscosity_scale=viscosity, stiffness_scale=stiffness
        )
    )
    return {"domain": fields, "val_rms_cm": val_rms_cm, "method": method}


# ------------------------------------------------------------------ the Domain from a file


def test_a_domain_file_is_an_identify_json_or_a_plain_domain(tmp_path):
    """identify.json: its one method's fit, or of several the one with the lowest held-out tip
    RMS; a plain {"domain": {...}}: its fields, the rest at their defaults. Either way named
    "identified", with the file's sha256 and the method kept for the callers to record."""
    both = _identify_json(
        tmp_path / "both.json",
        {
            "search": _result(20.0, 1.0, 3e-4, "search"),
            "gradient": _result(19.0, 0.9, 2e-4, "gradient"),
        },
    )
    read = domains.read_domain_file(both)
    assert read.domain == mjx_arm.Domain(
        name="identified", viscosity_scale=19.0, stiffness_scale=0.9
    )
    assert read.method == "gradient" and read.path == str(both)
    assert read.sha256 == hashlib.sha256(both.read_bytes()).hexdigest()
    assert read.record()["domain"]["stiffness_scale"] == 0.9
    assert read.record()["method"] == "gradient"
    one = _identify_json(tmp_path / "one.json", {"search": _result(20.0, 1.0, 3e-4, "search")})
    assert domains.read_domain_file(one).domain.viscosity_scale == 20.0
    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps({"domain": {"name": "aged", "stiffness_scale": 0.7}}))
    read = domains.read_domain_file(plain)
    assert read.domain == mjx_arm.Domain(name="identified", stiffness_scale=0.7)
    assert read.method is None and read.domain.viscosity_scale == 1.0
    # The committed identification of D_c: the search's exact fit, not the gradient's copy.
    committed = domains.read_domain_file(COMMITTED_IDENTIFY / "identify.json")
    assert committed.method == "search"
    assert committed.domain.viscosity_scale == pytest.approx(20.1169, rel=1e-5)
    # Another file, another digest: what a run records says which identification taught it.
    assert committed.sha256 != read.sha256


@pytest.mark.parametrize(
    ("content", "error", "message"),
    [
        (None, FileNotFoundError, "no such file"),
        (b"{not json", ValueError, "is not JSON"),
        (b"[1, 2]", ValueError, "expected a JSON object, got list"),
        (b'{"viscosity_scale": 3}', ValueError, "neither an identify.json"),
        (b'{"results": {}}', ValueError, "an identify.json without results"),
        (b'{"results": {"search": {"values": {}}}}', ValueError, "hold no fitted domain"),
        (b'{"domain": [1]}', ValueError, "its domain is not a JSON object"),
        (b'{"domain": {"viscosity": 1, "damping": 2}}', ValueError, "unknown Domain fields"),
        (b'{"domain": {"stiffness_scale": -0.5}}', ValueError, "finite and > 0"),
        (b'{"domain": {"stiffness_scale": "soft"}}', ValueError, "must be a real number"),
        (b'{"domain": {"mass_scale": true}}', ValueError, "must be a real number"),
        (b'{"domain": {"viscosity_scale": NaN}}', ValueError, "finite and > 0"),
    ],
)
def test_bad_domain_files_are_refused_in_one_line(tmp_path, content, error, message):
    path = tmp_path / "domain.json"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(error, match=message) as err:
        domains.read_domain_file(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_several_fits_without_a_held_out_score_are_refused(tmp_path):
    fit = _result(20.0, 1.0, 3e-4, "search")
    unscored = fit | {"val_rms_cm": None}
    path = _identify_json(tmp_path / "i.json", {"search": fit, "gradient": unscored})
    with pytest.raises(ValueError, match="result 'gradient' has no held-out tip RMS"):
        domains.read_domain_file(path)


# ------------------------------------------------------------------ k chosen in the taught arm


def test_k_is_stretch_onlys_best_on_the_validation_program_in_the_taught_arm(small_xml):
    """choose_hold_factor: the candidate with the lowest X_err of the validation program held
    k periods, rolled out in the arm given (the identified one), not in another."""
    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    taught = mjx_arm.load(
        xml=small_xml, domain=mjx_arm.Domain(name="identified", viscosity_scale=4.0)
    )
    config = dataclasses.replace(
        distill.DistillConfig(), k_candidates=(1, 3, 6), k_choice_seconds=2.0
    )
    k, record = distill.choose_hold_factor(config, [], arm_s, taught, log=lambda _: None)
    program = programs.validation_program(2.0)
    target = arm_s.rollout(program, backend="c")

    def x_err(arm, k):
        poses = arm.rollout(np.repeat(program, k, axis=0), backend="c")[k - 1 :: k]
        return float(position_error_cm(poses, target).mean())

    want = {c: x_err(taught, c) for c in (1, 3, 6)}
    assert k == min(want, key=want.get) and record["k"] == k
    np.testing.assert_allclose([record["x_err_cm_by_k"][str(c)] for c in want], list(want.values()))
    assert record["candidates"] == [1, 3, 6] and record["domain"]["viscosity_scale"] == 4.0
    assert record["program"] == "mjx_arm.programs.validation_program(2)"
    # Another arm scores the candidates otherwise: the choice was made in the taught one.
    other = mjx_arm.load(xml=small_xml, domain="constrained")
    assert x_err(other, 3) != pytest.approx(want[3], rel=1e-3)
    # Without candidates: the set k, else the translators' own.
    fixed = distill.DistillConfig(hold_factor=4)
    assert distill.choose_hold_factor(fixed, [], arm_s, taught) == (4, None)


def test_k_candidates_are_checked_with_the_settings():
    with pytest.raises(distill.ConfigError, match="k_candidates choose k or set it"):
        distill.DistillConfig(hold_factor=15, k_candidates=(10, 15))
    with pytest.raises(distill.ConfigError, match="k_candidates must be distinct integers"):
        distill.DistillConfig(k_candidates=(10, 10))
    with pytest.raises(distill.ConfigError, match="k_candidates must be distinct integers >= 1"):
        distill.DistillConfig(k_candidates=(0, 5))
    with pytest.raises(distill.ConfigError, match="k_choice_seconds"):
        distill.DistillConfig(k_candidates=(5,), k_choice_seconds=0.0)


# ------------------------------------------------------------------ taught on a file


def test_a_distillation_taught_on_a_file_domain_plans_there_records_it_and_keys_its_cache(
    tmp_path, capsys
):
    """--teach-domain: the teacher plans in the file's arm (its commands are that arm's), k is
    chosen there (distill.json and every file record the X_err by k), the files stay labelled for
    --domain and record the file, its sha256 and the taught values; the teacher's cache is keyed
    on those values, so another file's teacher is planned again and the first one kept."""
    taught_file = tmp_path / "identified.json"
    fields = {"viscosity_scale": 15.0, "stiffness_scale": 0.9}
    taught_file.write_text(json.dumps({"domain": fields}))
    out = tmp_path / "run"
    common = ["--out", str(out), "--n-train", "2", "--n-val", "1", "--duration-s", "0.5"]
    common += ["--batch-size", "2", "--k-candidates", "2", "3", "--k-choice-seconds", "2"]
    args = ["--translators", str(translator_path()), "--epochs", "1", "--eval-every", "1"]
    distill.main(args + common + ["--teach-domain", str(taught_file)])

    taught_domain_ = mjx_arm.Domain(name="identified", viscosity_scale=15.0, stiffness_scale=0.9)
    arm_s = mjx_arm.load(domain="source")
    arm_taught = mjx_arm.load(domain=taught_domain_)
    run = json.loads((out / "distill.json").read_text())
    k = run["history"]["k"]
    choice = run["history"]["k_choice"]
    assert choice["k"] == k and set(choice["x_err_cm_by_k"]) == {"2", "3"}
    assert k == min((2, 3), key=lambda c: choice["x_err_cm_by_k"][str(c)])
    assert choice["domain"] == dataclasses.asdict(taught_domain_)
    record = run["taught_domain"]
    assert record["sha256"] == hashlib.sha256(taught_file.read_bytes()).hexdigest()
    assert record["domain"] == dataclasses.asdict(taught_domain_) and record["method"] is None
    assert record["values"]["viscosity_scale"] == pytest.approx(15.0)
    assert record["values"]["stiffness_scale"] == 0.9
    _, meta = checkpoint.load(out / "translator_seed0.ckpt")
    assert meta["target_domain"] == "constrained" and meta["method"] == "distill"
    assert meta["k"] == k and taught_domain(meta) == record
    assert meta["finetune"]["k_choice"] == choice
    # The teacher planned in the taught arm: its cache's key names that Domain, and its
    # commands are the ones planned there afresh (MuJoCo C, deterministic).
    with np.load(out / "teacher.npz") as f:
        key = json.loads(str(f["key"]))
        c_train = f["c_train"].copy()
    assert key["domain"] == dataclasses.asdict(taught_domain_) and key["k"] == k
    config = distill.DistillConfig(n_train=2, n_val=1, duration_s=0.5, batch_size=2, hold_factor=k)
    fresh = distill.teacher_data(config, arm_s, arm_taught, k, None, log=lambda _: None)
    np.testing.assert_array_equal(fresh["c_train"], c_train)
    constrained = mjx_arm.load(domain="constrained")
    there = distill.teacher_data(config, arm_s, constrained, k, None, log=lambda _: None)
    assert np.abs(there["c_train"] - c_train).max() > 1e-3  # the true arm would teach otherwise

    # Another identification in the same folder: planned again, the first teacher set aside.
    other_file = tmp_path / "other.json"
    other_file.write_text(json.dumps({"domain": {"viscosity_scale": 25.0}}))
    capsys.readouterr()
    distill.main(["--teacher-only", "--teach-domain", str(other_file)] + common)
    assert "domain.viscosity_scale: stored 15.0, this run 25.0" in capsys.readouterr().out
    (aside,) = out.glob("teacher.identified-*.npz")
    with np.load(aside) as f:
        np.testing.assert_array_equal(f["c_train"], c_train)
    with np.load(out / "teacher.npz") as f:
        assert json.loads(str(f["key"]))["domain"]["viscosity_scale"] == 25.0


def test_a_bad_teach_domain_is_a_usage_error_before_any_arm_loads(tmp_path, monkeypatch, capsys):
    def no_work(*args, **kwargs):
        raise AssertionError("work started")

    monkeypatch.setattr(distill, "start_stage", no_work)
    bad = tmp_path / "bad.json"
    bad.write_text('{"domain": {"stiffness_scale": 0}}')
    for path, message in ((bad, "finite and > 0"), (tmp_path / "none.json", "no such file")):
        with pytest.raises(SystemExit) as refused:
            distill.main(
                ["--translators", str(translator_path()), "--out", str(tmp_path / "o")]
                + ["--teach-domain", str(path), "--k-candidates", "10", "15"]
            )
        err = capsys.readouterr().err.strip().splitlines()[-1]
        assert refused.value.code == 2 and "--teach-domain" in err and message in err


# ------------------------------------------------------------------ scored in the true target


@pytest.fixture()
def distilled_pair(small_xml, tmp_path):
    """Two distilled files of the same G_c (the solid-disc arm's CCGAN-GP, labelled for the
    3-segment arm, k = 2): one taught in the target (privileged), one recording a Domain file
    whose values are far from the target's."""
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    tree, meta = checkpoint.load(SOLID_TRANSLATORS_DIR / "ccgan" / "translator.ckpt")
    labels = {
        "method": "distill",
        "source_domain": "source",
        "target_domain": "constrained",
        "model_hash": arm_c.model_hash,
        "k": 2,
    }
    stage = {"method": "distill", "model_hash": arm_c.model_hash, "domain": "constrained"}
    sim = checkpoint.save(tmp_path / "sim.ckpt", tree, meta | labels | {"finetune": stage})
    record = {
        "path": "identify.json",
        "sha256": "ab" * 32,
        "method": "search",
        "domain": dataclasses.asdict(mjx_arm.Domain(name="identified", viscosity_scale=3.0)),
        "values": {"viscosity_scale": 3.0, "stiffness_scale": 0.8, "mass_scale": 1.0},
    }
    finetune = stage | {"taught_domain": record}
    ident = checkpoint.save(tmp_path / "ident.ckpt", tree, meta | labels | {"finetune": finetune})
    return sim, ident, record


def test_the_identified_translator_is_scored_in_the_true_target(
    small_xml, tmp_path, distilled_pair
):
    """ccgan_ident runs its commands in the true --target-domain at the k its file holds: the
    same G_c scores exactly as the privileged file, whatever the taught arm was, and as its
    commands rolled out in the target by hand; the report names it and sets the identified
    values beside the truth."""
    sim, ident, record = distilled_pair
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("stretch", "ccgan_sim", "ccgan_ident"),
        seeds=(0,),
        duration_s=2.0,
        hold_factors=(1, 2),
        validation_duration_s=1.0,
        robustness=False,
        plots=False,
        ccgan_sim_path=str(sim),
        ccgan_ident_path=str(ident),
        out_dir=str(tmp_path / "eval"),
        xml=small_xml,
    )
    results = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    row = results["table"]["circle"]["ccgan_ident"]
    assert row["k"] == 2 and results["methods_run"] == ["stretch", "ccgan_sim", "ccgan_ident"]
    arm_s, arm_c = pipeline.load_arms(cfg)
    program = programs.circle(2.0)
    target = arm_s.rollout(program, backend="c")
    translator = methods.load_translator("ccgan_ident", cfg)[0]
    commands, k = translator.translate(program, target, seed=0)
    by_hand = metrics.tracking_errors(held.run_dc(arm_c, commands, k, "c"), target)
    assert row["x_err_cm_mean"] == pytest.approx(by_hand["x_err_cm_mean"], rel=1e-9)
    assert row["x_err_cm_mean"] == results["table"]["circle"]["ccgan_sim"]["x_err_cm_mean"]
    taught = results["taught_domains"]["ccgan_ident"]
    truth = arm_c.mj_model.opt.viscosity / arm_s.mj_model.opt.viscosity
    assert taught["truth"]["viscosity_scale"] == pytest.approx(truth)
    assert taught["error_pct"]["viscosity_scale"] == pytest.approx(100 * (3.0 / truth - 1))
    assert taught["error_pct"]["stiffness_scale"] == pytest.approx(-20.0)
    assert taught["sha256"] == record["sha256"] and list(taught["files"]) == [str(ident)]
    assert "ccgan_sim" not in results["taught_domains"]
    md = (tmp_path / "eval" / "shapes.md").read_text()
    assert "## Taught on the identified arm (data-only)" in md
    assert 'ccgan_ident ("distilled (identified arm)") was distilled on an arm identified' in md
    assert "the privileged upper bound" in md
    assert f"| viscosity_scale (medium viscosity / the source medium's) | 3 | {truth:.5g} |" in md
    assert "- distilled (identified arm) against distilled: lower mean X_err on 0 of 1" in md


def test_each_distilled_method_refuses_the_other_ones_file_and_another_target(
    small_xml, distilled_pair
):
    sim, ident, _ = distilled_pair
    base = {"xml": small_xml, "seeds": (0,)}
    with pytest.raises(methods.TranslatorError, match="score it as ccgan_ident"):
        methods.load_translator("ccgan_sim", pipeline.EvalConfig(ccgan_sim_path=str(ident), **base))
    with pytest.raises(methods.TranslatorError, match="score it as ccgan_sim"):
        methods.load_translator(
            "ccgan_ident", pipeline.EvalConfig(ccgan_ident_path=str(sim), **base)
        )
    aged = pipeline.EvalConfig(ccgan_ident_path=str(ident), target_domain="aged", **base)
    with pytest.raises(methods.TranslatorError, match="expects target_domain 'aged'"):
        methods.load_translator("ccgan_ident", aged)


def test_the_identified_path_is_a_flag_of_eval_shapes(tmp_path, distilled_pair):
    from eval import shapes

    _, ident, _ = distilled_pair
    argv = ["--methods", "stretch", "ccgan_ident", "--identified-path", str(ident)]
    cfg = shapes.parse_args(argv + ["--out", str(tmp_path)])
    assert cfg.ccgan_ident_path == str(ident) and cfg.methods == ("stretch", "ccgan_ident")
    with pytest.raises(SystemExit):
        shapes.parse_args(["--identified-path", str(tmp_path / "no.ckpt"), "--out", str(tmp_path)])


# ------------------------------------------------------------------ the chain's stages


def _without(args, flags) -> list[str]:
    """A command's arguments less the named flags and their values."""
    out, skipping = [], False
    for arg in args:
        if arg.startswith("--"):
            skipping = arg in flags
        if not skipping:
            out.append(arg)
    return out


@pytest.mark.parametrize("config", ["quick.json", "paper.json"])
def test_the_chains_identified_stages(config, tmp_path, capsys):
    """identify_c fits the D_c babbling from the paper's nominal medium (not the truth);
    teacher_ident and ident_sim are teacher_c and ccgan_sim taught on its identify.json with k
    chosen there; table_ident scores the two distilled translators side by side. Every other
    setting is the privileged stages' own, and the chain lists them."""
    _, stages = load_config(paper.REPO / "experiments" / config)
    by_name = {s.name: s for s in stages}
    assert by_name["identify_c"].module == "mjx_arm.identify"
    identify_args = " ".join(by_name["identify_c"].args)
    assert "{stage:data_paper}/babble --domain constrained" in identify_args
    assert "--base-viscosity-scale 10" in identify_args
    teach = "--teach-domain {stage:identify_c}/identify.json"
    for new, old in (("teacher_ident", "teacher_c"), ("ident_sim", "ccgan_sim")):
        args = " ".join(by_name[new].args)
        assert teach in args and "--k-candidates 10 15 20" in args and "--hold-factor" not in args
        flags = ("--teach-domain", "--k-candidates", "--k-choice-seconds")
        ours = _without(by_name[new].args, flags)
        theirs = _without(by_name[old].args, ("--hold-factor",))
        assert ours == [a.replace("{stage:teacher_c}", "{stage:teacher_ident}") for a in theirs]
        assert by_name[new].gpu == by_name[old].gpu
    assert by_name["ident_sim"].inputs == ("ccgan", "identify_c", "teacher_ident")
    table = " ".join(by_name["table_ident"].args)
    assert "--identified-path {stage:ident_sim}/translator.ckpt" in table
    assert "--ccgan-sim-path {stage:ccgan_sim}/translator.ckpt" in table
    assert report.IDENT_TABLE_STAGE == "table_ident"
    # The chain lists them, each waiting for its inputs.
    capsys.readouterr()
    argv = ["--out", str(tmp_path / "run"), "--config", str(paper.REPO / "experiments" / config)]
    assert paper.main(argv + ["--list"]) == 0
    listed = capsys.readouterr().out
    assert "ident_sim      todo (waits for ccgan, identify_c, teacher_ident)" in listed
    chain = Chain(stages, tmp_path / "run", paper.REPO)
    assert "identify.json" in shlex.join(chain.command("ident_sim", tmp_path / "x"))


def test_the_chain_report_sets_the_identified_translator_beside_the_privileged_one():
    rows = {
        "none": 5.0,
        "stretch": 1.0,
        "ccgan_sim": 0.4,
        "ccgan_ident": 0.5,
    }
    results = {
        "methods_run": list(rows),
        "config": {"target_domain": "constrained"},
        "table": {
            s: {
                m: {
                    "x_err_cm_mean": x,
                    "phi_err_rad_mean": 0.1,
                    "k": 15,
                    "target_excursion_cm": 5.0,
                    "x_err_pct_of_excursion": 20 * x,
                }
                for m, x in rows.items()
            }
            for s in ("circle", "kite")
        },
        "taught_domains": {
            "ccgan_ident": {
                "path": "DIR/identify_c/identify.json",
                "sha256": "cd" * 32,
                "method": "search",
                "values": {"viscosity_scale": 20.0, "stiffness_scale": 1.0, "mass_scale": 1.0},
                "truth": {"viscosity_scale": 20.1169, "stiffness_scale": 1.0, "mass_scale": 1.0},
                "error_pct": {"viscosity_scale": -0.581, "stiffness_scale": 0.0, "mass_scale": 0.0},
            }
        },
    }
    lines = report.ident_lines(results)
    assert not [line for line in lines if line.startswith("#")]  # under paper.md's heading
    assert "- distilled (identified arm) / distilled: 1.25-1.25" in lines
    assert "- distilled (identified arm) / stretch only: 0.50-0.50" in lines
    head = next(line for line in lines if line.startswith("| shape | untranslated"))
    assert "distilled (identified arm) (k = 15)" in head
    row = "| viscosity_scale (medium viscosity / the source medium's) | 20 | 20.117 | -0.581% |"
    assert row in lines
