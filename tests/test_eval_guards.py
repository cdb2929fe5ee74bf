"""Guards of eval.shapes: nothing overwritten, nothing mixed, no wrong answer with exit status 0.

A quick run never writes results/, every setting is refused before any work, a translator that
was asked for must load, reports state their lengths and arm, and long jobs show progress.
"""

import dataclasses
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import mjx_arm  # noqa: F401  (before jax)
from eval import methods, pipeline, plots, report, shapes
from mjx_arm import constants
from tracking.config import ConfigError
from tracking.oracle import OracleConfig

ROOT = Path(__file__).resolve().parent.parent
#: The solid-disc arm's CCGAN-GP: its files record no arm, so it runs on the tests' small arms.
SHIPPED = ROOT / "results" / "solid" / "translators" / "ccgan" / "translator.ckpt"


def _labels(method, target_domain, model_hash) -> dict:
    """What a translator file records of itself (`ccgan.translator.LABELS`)."""
    return {
        "method": method,
        "source_domain": "source",
        "target_domain": target_domain,
        "model_hash": model_hash,
    }


def _file_hash(path) -> str:
    """The model hash `mjx_arm.load` gives a file: sha256 of its text, first 16 hex digits."""
    return hashlib.sha256(Path(path).read_text().encode()).hexdigest()[:16]


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    """Runs the test in an empty folder, with no translator chosen through the environment."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    return tmp_path


def test_quick_run_defaults_to_a_new_run_folder_never_results(in_tmp):
    cfg = shapes.parse_args(["--quick", "--render"])
    assert cfg.quick and cfg.duration_s == 10.0 and cfg.seeds == (0,) and cfg.out_dir is None
    first, second = pipeline.output_dir(cfg), pipeline.output_dir(cfg)
    for out in (first, second):
        assert out.parent == Path(pipeline.RUNS_DIR) and out.name.startswith("quick-")
        assert out.is_dir()
    assert first != second  # two quick runs never share (and overwrite) a folder
    # Other settings than the main job's: a run folder too.
    custom = pipeline.output_dir(shapes.parse_args(["--duration", "30"]))
    assert custom.parent == Path(pipeline.RUNS_DIR) and custom.name.startswith("custom-")
    assert not Path("results").exists()
    # The main job (with or without videos) regenerates results/; --out is always obeyed.
    assert pipeline.output_dir(shapes.parse_args(["--render"])) == Path("results")
    assert pipeline.output_dir(shapes.parse_args([])) == Path("results")
    assert pipeline.output_dir(shapes.parse_args(["--quick", "--out", "results"])) == Path(
        "results"
    )


def test_noise_levels_default_per_machine_and_other_levels_make_a_custom_run(in_tmp):
    """On a CPU the main job's noise test keeps the largest level (CPU_NOISE_STDS): the default
    command is still the main job; --noise-stds picks others, in a run folder of its own; a
    negative level is a usage error before any work."""
    cfg = shapes.parse_args(["--render"])
    assert cfg.noise_stds == pipeline.CPU_NOISE_STDS == pipeline.main_job_config().noise_stds
    assert pipeline.is_main_job(cfg)
    every = shapes.parse_args(["--noise-stds", "0.1", "0.3", "0.5"])
    assert every.noise_stds == (0.1, 0.3, 0.5) and not pipeline.is_main_job(every)
    assert pipeline.output_dir(every).parent == Path(pipeline.RUNS_DIR)
    with pytest.raises(SystemExit) as refused:
        shapes.parse_args(["--noise-stds", "-0.1"])
    assert refused.value.code == 2


def test_quick_run_is_marked_and_states_its_arm_and_lengths(in_tmp, capsys):
    """A tiny quick run on the default arm: a run folder, marked plots and report, the I-Support
    arm named, every length from the config, progress bars on stderr."""
    cfg = pipeline.quick(
        pipeline.EvalConfig(
            shapes=("circle",),
            methods=("none", "stretch"),
            duration_s=1.0,
            hold_factors=(1, 2),
            validation_duration_s=0.5,
            robustness=False,
        )
    )
    data = pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    (out,) = Path(pipeline.RUNS_DIR).iterdir()
    assert out.name.startswith("quick-") and not Path("results").exists()
    assert data["config"]["out_dir"] == str(out)
    # The default arm is the I-Support one the committed translators were trained on.
    assert data["model_hash"] == _file_hash(constants.DEFAULT_MODEL_PATH)
    assert data["model"]["file"] == "models/softarm.xml"
    md = (out / "shapes.md").read_text()
    assert "QUICK RUN: 1 s programs, seeds [0]" in md
    assert "`models/softarm.xml`, the I-Support arm" in md
    assert "0.5 s validation program" in md and "20 s validation" not in md
    assert json.loads((out / "shapes.json").read_text())["config"]["quick"] is True
    figures = [out / f for f in data["figures"]]
    assert figures
    for png in figures:
        assert Image.open(png).text.get("Comment", "").startswith("QUICK RUN"), png
    err = capsys.readouterr().err
    assert "stretch k on the validation program" in err and "D_c rollouts" in err


@pytest.mark.parametrize("folder", ["results", "results/solid"])
def test_committed_report_regenerates_and_its_lengths_come_from_the_config(folder):
    """The main job's report, and the solid-disc arm's kept beside it."""
    results = json.loads((ROOT / folder / "shapes.json").read_text())
    assert report.markdown_report(results) == (ROOT / folder / "shapes.md").read_text()
    results["config"]["validation_duration_s"] = 10.0
    md = report.markdown_report(results)
    assert "on a 10 s validation program" in md and "20 s validation" not in md
    results["config"].update(quick=True, duration_s=10.0, seeds=[0])
    assert "QUICK RUN: 10 s programs, seeds [0]" in report.markdown_report(results)


def test_figures_of_a_quick_run_carry_the_mark(tmp_path):
    t = np.linspace(0, 1, 20)
    target = np.stack(
        [0.01 * np.cos(t), 0.01 * np.sin(t), -0.2 + 0 * t] + [0 * t] * 2 + [1 + 0 * t]
    )
    traj = {"target": target.T, "poses": {"stretch": target.T + 1e-3}}
    plots.paths_figure("circle", traj, tmp_path / "plain.png")
    plots.paths_figure("circle", traj, tmp_path / "marked.png", "QUICK RUN: test")
    plain, marked = (Image.open(tmp_path / f"{n}.png") for n in ("plain", "marked"))
    assert "Comment" not in plain.text and marked.text["Comment"] == "QUICK RUN: test"
    changed = np.abs(np.asarray(plain, float) - np.asarray(marked, float)).max(-1) > 60
    assert changed.sum() > 2000  # visible: the mark's letters, across the figure


@pytest.mark.parametrize(
    ("argv", "flag", "reason"),
    [
        (["--hold-factors", "0"], "--hold-factors", ">= 1, got (0,)"),
        (["--hold-factors", "5", "5"], "--hold-factors", "distinct"),
        (["--methods", "bogus"], "--methods", "invalid choice"),
        (["--robust-methods", "none"], "--robust-methods", "distinct ones of"),
        (["--robust-methods", "ccgan", "ccgan"], "--robust-methods", "distinct"),
        (["--shapes", "square"], "--shapes", "invalid choice"),
        (["--duration", "0"], "--duration", "at least one 0.1 s command"),
        (["--duration", "-5"], "--duration", "at least one 0.1 s command"),
        (["--duration", "nan"], "--duration", "at least one 0.1 s command"),
        (["--seeds"], "--seeds", "expected at least one argument"),
        (["--seeds", "-1"], "--seeds", ">= 0"),
        (["--seeds", "1", "1"], "--seeds", "distinct"),
        (["--out", "a_file"], "--out", "not a folder"),
        (["--model", "nope.xml"], "--model", "names no file"),
        (["--ccgan-path", "nope.ckpt"], "--ccgan-path", "names no file"),
        (["--wcgan-path", "nope.ckpt"], "--wcgan-path", "names no file"),
        (["--distilled-path", "nope.ckpt"], "--distilled-path", "names no file"),
        # The old name of --distilled-path is still accepted.
        (["--ccgan-sim-path", "nope.ckpt"], "--distilled-path", "names no file"),
        (["--methods", "none", "--oracle-per-period"], "--oracle-per-period", "add oracle"),
        (["--oracle-steps", "0"], "--oracle-steps", ">= 1, got 0"),
        (["--oracle-lr", "-1"], "--oracle-lr", "> 0"),
        (["--oracle-horizon", "nan"], "--oracle-horizon", "at least one 0.1 s command"),
    ],
)
def test_bad_options_are_usage_errors_before_any_work(in_tmp, capsys, argv, flag, reason):
    Path("a_file").write_text("not a folder")
    with pytest.raises(SystemExit) as exc:
        shapes.parse_args(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "usage: python -m eval.shapes" in err and flag in err and reason in err, err
    assert sorted(p.name for p in in_tmp.iterdir()) == ["a_file"]  # nothing written


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"hold_factors": (0,)}, "hold_factors"),
        ({"hold_factors": ()}, "hold_factors"),
        ({"methods": ("bogus",)}, "methods"),
        ({"methods": ()}, "methods"),
        ({"shapes": ("square",)}, "shapes"),
        ({"seeds": ()}, "seeds"),
        ({"duration_s": 0.0}, "duration_s"),
        ({"validation_duration_s": -1.0}, "validation_duration_s"),
        ({"noise_stds": (-0.1,)}, "noise_stds"),
        ({"n_repeats": 0}, "n_repeats"),
        ({"backend": "gpu"}, "backend"),
        ({"target_domain": "source"}, "target_domain"),
        ({"out_dir": "a_file"}, "out_dir"),
        ({"model_path": "nope.xml"}, "model_path"),
        ({"ccgan_path": "nope.ckpt"}, "ccgan_path"),
        ({"video_fps": 0}, "video_fps"),
    ],
)
def test_eval_config_refuses_bad_settings(in_tmp, kwargs, field):
    Path("a_file").write_text("not a folder")
    with pytest.raises(ConfigError) as exc:
        pipeline.EvalConfig(**kwargs)
    assert exc.value.field == field


def test_oracle_config_refuses_bad_settings():
    for kwargs in ({"steps": 0}, {"learning_rate": 0.0}, {"horizon_s": 0.0}, {"init": "zeros"}):
        with pytest.raises(ConfigError):
            OracleConfig(**kwargs)


def test_help_names_the_program_and_shows_every_default():
    parser = shapes.build_parser()
    assert parser.prog == "python -m eval.shapes"
    assert "REWRITES the committed results in results/" in parser.description
    formatter = parser._get_formatter()
    for action in parser._actions:
        if action.dest == "help":
            continue
        text = formatter._get_help_string(action)
        # Switches are off unless given; every other option shows its default.
        assert action.help and ("default" in text or action.nargs == 0), action.option_strings


def test_a_translator_that_was_asked_for_must_load(small_xml, tmp_path, monkeypatch):
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    bad = tmp_path / "bad.ckpt"
    bad.write_bytes(b"not a checkpoint")
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "ccgan"),
        ccgan_path=str(bad),
        duration_s=1.0,
        hold_factors=(1,),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        xml=small_xml,
        out_dir=str(tmp_path / "out"),
    )
    with pytest.raises(methods.TranslatorError, match="does not load"):
        pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    assert not (tmp_path / "out").exists()  # stopped before any work or file
    # $CCGAN_TRANSLATOR is a choice too: a missing file there is an error, not a skip.
    monkeypatch.setenv("CCGAN_TRANSLATOR", str(tmp_path / "nope.ckpt"))
    with pytest.raises(methods.TranslatorError, match="no translator checkpoint"):
        methods.load_translator("ccgan", pipeline.EvalConfig(methods=("ccgan",)))
    # From the command line: a non-zero exit naming the file.
    monkeypatch.delenv("CCGAN_TRANSLATOR")
    argv = ["--methods", "none", "ccgan", "--ccgan-path", str(bad), "--shapes", "circle"]
    argv += ["--duration", "0.5", "--no-robustness", "--out", str(tmp_path / "cli")]
    with pytest.raises(SystemExit) as exc:
        shapes.main(argv)
    assert exc.value.code not in (0, None) and "does not load" in str(exc.value.code)
    assert not (tmp_path / "cli").exists()


def test_missing_default_translators_are_skipped_with_a_note(tmp_path, monkeypatch):
    """Only a default checkpoint may be absent; the note names the file and the flag."""
    import ccgan.translator

    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    missing = tmp_path / "missing" / "translator.ckpt"
    monkeypatch.setattr(ccgan.translator, "DEFAULT_PATH", missing)
    monkeypatch.setattr(methods, "CCGAN_SIM_DEFAULT_PATH", missing)
    monkeypatch.setattr(methods, "WCGAN_DEFAULT_PATH", missing)
    cfg = pipeline.EvalConfig()
    for method, flag in (
        ("ccgan", "--ccgan-path"),
        ("ccgan_sim", "--distilled-path"),
        ("wcgan", "--wcgan-path"),
    ):
        tr, why = methods.load_translator(method, cfg)
        assert tr is None and str(missing) in why and flag in why, why
    # A default that is there but does not load is an error, not a skip.
    missing.parent.mkdir()
    missing.write_bytes(b"corrupt")
    with pytest.raises(methods.TranslatorError, match="does not load"):
        methods.load_translator("wcgan", cfg)


def test_wcgan_default_path_never_calls_the_loader_with_kind(tmp_path, monkeypatch):
    """The WCGAN-GP default: absent -> skipped without calling `ccgan.load_translator` (which
    takes no `kind`); present -> loaded from it, with the trained seeds beside it."""
    import ccgan

    calls = []
    real = ccgan.load_translator

    def spy(*args, **kwargs):
        calls.append(kwargs)
        return real(*args, **kwargs)

    monkeypatch.setattr(ccgan, "load_translator", spy)
    default = tmp_path / "wcgan" / "translator.ckpt"
    monkeypatch.setattr(methods, "WCGAN_DEFAULT_PATH", default)
    cfg = pipeline.EvalConfig(seeds=(0, 1), trust_unlabelled_translators=True)
    tr, why = methods.load_translator("wcgan", cfg)
    assert tr is None and calls == [] and str(default) in why
    default.parent.mkdir()
    for name in ("translator.ckpt", "translator_seed0.ckpt", "translator_seed1.ckpt"):
        shutil.copy(SHIPPED, default.parent / name)
    tr, why = methods.load_translator("wcgan", cfg)
    assert sorted(tr.trained_seeds) == [0, 1], why
    assert all("kind" not in c for c in calls)
    rest = np.tile([0.0, 0.0, -0.2, 0.0, 0.0, 1.0], (4, 1))  # tip (m), unit d3
    commands, k = tr.translate(np.full((4, 3), 1.0), rest, seed=1)
    assert commands.shape == (4 * k, 3)


def test_translators_trained_on_another_arm_are_refused(small_xml, tmp_path, monkeypatch):
    """A translator file that records its arm's model hash is scored only on that arm."""
    from ccgan import checkpoint

    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    tree, meta = checkpoint.load(SHIPPED)
    small_hash = hashlib.sha256(small_xml.encode()).hexdigest()[:16]
    for name, recorded in (("other.ckpt", "0123456789abcdef"), ("same.ckpt", small_hash)):
        checkpoint.save(tmp_path / name, tree, meta | _labels("ccgan", "constrained", recorded))
    cfg = pipeline.EvalConfig(
        shapes=("circle",),
        methods=("none", "ccgan"),
        ccgan_path=str(tmp_path / "other.ckpt"),
        seeds=(0,),
        duration_s=0.5,
        hold_factors=(1,),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        xml=small_xml,
        out_dir=str(tmp_path / "out"),
    )
    with pytest.raises(methods.TranslatorError, match="0123456789abcdef"):
        pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    assert not (tmp_path / "out").exists()
    same = dataclasses.replace(cfg, ccgan_path=str(tmp_path / "same.ckpt"))
    data = pipeline.evaluate(same, command="test", log=lambda *_: None)
    assert "ccgan" in data["methods_run"] and (tmp_path / "out" / "shapes.md").exists()


def test_default_arm_is_the_isupport_one_and_model_path_is_used(small_xml, tmp_path):
    """The default arm is models/softarm.xml, the committed translators' arm; the previous
    (linear-law) and solid-disc arms are named with where their translators are."""
    assert constants.TRANSLATOR_MODEL_PATH == constants.DEFAULT_MODEL_PATH
    assert pipeline.EvalConfig().model_path == str(constants.DEFAULT_MODEL_PATH)
    assert shapes.parse_args([]).model_path == str(constants.DEFAULT_MODEL_PATH)
    described = pipeline.model_description(pipeline.EvalConfig())
    assert described == {
        "file": "models/softarm.xml",
        "note": "the I-Support arm under the paper's Cosserat law (the default model)",
    }
    linear = pipeline.model_description(
        pipeline.EvalConfig(model_path=str(constants.LINEAR_LAW_MODEL_PATH))
    )
    assert linear["file"] == "models/softarm_linear.xml"
    assert "without stretch factors" in linear["note"] and "results/paper/run/" in linear["note"]
    solid = pipeline.model_description(
        pipeline.EvalConfig(model_path=str(constants.SOLID_MODEL_PATH))
    )
    assert solid["file"] == "models/softarm_solid.xml"
    assert "results/solid/translators/" in solid["note"]
    other = tmp_path / "small.xml"
    other.write_text(small_xml)
    cfg = pipeline.EvalConfig(model_path=str(other))
    arm_s, arm_c = pipeline.load_arms(cfg)
    assert arm_s.model_hash == arm_c.model_hash == _file_hash(other)
    assert pipeline.model_description(cfg)["note"] == (
        "not the arm the committed translators were trained on (models/softarm.xml)"
    )
    # MJCF text wins over the file.
    arm_x, _ = pipeline.load_arms(pipeline.EvalConfig(xml=small_xml, model_path="ignored.xml"))
    assert arm_x.model_hash == hashlib.sha256(small_xml.encode()).hexdigest()[:16]


def test_importing_eval_leaves_mujoco_gl_to_mjx_arm():
    """MUJOCO_GL is chosen in one place, mjx_arm's guarded check: with no display and no libEGL
    to be found, importing eval (and its renderer) first leaves the variable unset, as importing
    mjx_arm does (MUJOCO_GL=egl would make mujoco fail to import there)."""
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MUJOCO_GL")}
    code = (
        "import ctypes.util\n"
        "ctypes.util.find_library = lambda name: None\n"
        "import eval, eval.pipeline, eval.render, os\n"
        "print('MUJOCO_GL=' + repr(os.environ.get('MUJOCO_GL')))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr
    assert "MUJOCO_GL=None" in out.stdout.splitlines()


def _translator_run(small_xml, tmp_path, **kw):
    """A one-shape, half-second evaluation on the small arm that writes nothing but tmp_path."""
    return pipeline.EvalConfig(
        shapes=("circle",),
        seeds=(0,),
        duration_s=0.5,
        hold_factors=(1,),
        validation_duration_s=0.5,
        robustness=False,
        plots=False,
        xml=small_xml,
        out_dir=str(tmp_path / "out"),
        **kw,
    )


@pytest.mark.parametrize(
    "method, recorded, target, wanted, found",
    [
        # The D_c-trained CCGAN-GP scored on the aged arm (eval.shapes --target-domain aged).
        ("ccgan", ("ccgan", "constrained"), "aged", "'aged'", "'constrained'"),
        # The aged pair's translator scored on D_c.
        ("ccgan", ("ccgan", "aged"), "constrained", "'constrained'", "'aged'"),
        # A WCGAN-GP file given as --ccgan-path, and the other way round.
        ("ccgan", ("wcgan", "constrained"), "constrained", "'ccgan'", "'wcgan'"),
        ("wcgan", ("ccgan", "constrained"), "constrained", "'wcgan'", "'ccgan'"),
        # A translator as trained given as the one distilled in the simulator.
        ("ccgan_sim", ("ccgan", "constrained"), "constrained", "'distill'", "'ccgan'"),
    ],
)
def test_translators_labelled_for_another_method_or_domain_are_refused(
    small_xml, tmp_path, monkeypatch, method, recorded, target, wanted, found
):
    """The wrong-exit-0 cases of issue 32: refused before any work, naming both values."""
    from ccgan import checkpoint

    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    tree, meta = checkpoint.load(SHIPPED)
    small_hash = hashlib.sha256(small_xml.encode()).hexdigest()[:16]
    path = checkpoint.save(tmp_path / "t.ckpt", tree, meta | _labels(*recorded, small_hash))
    cfg = _translator_run(
        small_xml,
        tmp_path,
        methods=("none", method),
        target_domain=target,
        **{f"{method}_path": str(path)},
    )
    with pytest.raises(methods.TranslatorError) as exc:
        pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    message = str(exc.value)
    key = "target_domain" if recorded[0] == methods.FILE_METHODS[method][0] else "method"
    assert f"expects {key} {wanted}" in message and f"the file has {found}" in message
    assert "t.ckpt" in message and methods.PATH_FLAGS[method] in message
    assert not (tmp_path / "out").exists()
    # Labelled as what it is scored as, the same file runs.
    right = _labels(methods.FILE_METHODS[method][0], target, small_hash)
    checkpoint.save(path, tree, meta | right)
    assert method in pipeline.evaluate(cfg, command="test", log=lambda *_: None)["methods_run"]


def _labelled_copy(tmp_path, name, method, **extra):
    """A copy of the shipped translator labelled as made by `method` for D_c on an arm of hash
    "0" * 16, with `extra` metadata (a distillation's "started_from")."""
    from ccgan import checkpoint

    tree, meta = checkpoint.load(SHIPPED)
    labels = _labels(method, "constrained", "0" * 16)
    checkpoint.save(tmp_path / name, tree, meta | labels | extra)
    return tmp_path / name


def test_a_translator_distilled_from_another_start_or_fine_tuned_is_refused_as_distilled(
    tmp_path, monkeypatch
):
    """The distilled translator is the CCGAN-GP one (labelled "distill"): a file distilled from
    the WCGAN-GP ("distill_from_wcgan") is refused with one line naming its label, and a file
    of the retired ccgan.finetune with one saying it was retired; the right label loads and its
    start is kept for the report."""
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    start = {"method": "wcgan", "path": "w/translator.ckpt", "sha256": "ab" * 32}
    wrong = _labelled_copy(tmp_path, "w.ckpt", "distill_from_wcgan", started_from=start)
    with pytest.raises(methods.TranslatorError) as exc:
        methods.load_translator("ccgan_sim", pipeline.EvalConfig(ccgan_sim_path=str(wrong)))
    message = str(exc.value)
    assert "\n" not in message and "w.ckpt" in message and "--distilled-path" in message
    assert "the file has 'distill_from_wcgan'" in message and "expects method 'distill'" in message
    retired = _labelled_copy(tmp_path, "f.ckpt", "finetune")
    with pytest.raises(methods.TranslatorError) as exc:
        methods.load_translator("ccgan_sim", pipeline.EvalConfig(ccgan_sim_path=str(retired)))
    assert "'finetune'" in str(exc.value) and "retired" in str(exc.value)
    right = _labelled_copy(tmp_path, "d.ckpt", "distill", started_from=start | {"method": "ccgan"})
    tr, _ = methods.load_translator("ccgan_sim", pipeline.EvalConfig(ccgan_sim_path=str(right)))
    assert tr.files == (right,) and tr.labels[0]["method"] == "distill"
    assert tr.labels[0]["started_from"]["method"] == "ccgan"


def test_the_arm_note_names_the_translator_files_loaded_not_a_constant(tmp_path, monkeypatch):
    """shapes.json's arm note says which files were scored, from the translators loaded: a
    file outside the committed run is named as it is, never as the committed run."""
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    path = _labelled_copy(tmp_path, "c.ckpt", "ccgan")
    cfg = pipeline.EvalConfig(ccgan_path=str(path))
    tr, _ = methods.load_translator("ccgan", cfg)
    note = pipeline.model_description(cfg, {"ccgan": tr})["note"]
    assert note.startswith(pipeline.ARM_NOTE + "; translators scored")
    assert f"CCGAN-GP from {path}" in note and "as their labels record" in note
    assert "rerun_2026" not in note
    unlabelled = methods.TranslatorMethod("ccgan_sim", tr._obj, files=(path,))
    note = pipeline.model_description(cfg, {"ccgan_sim": unlabelled})["note"]
    assert f"distilled from {path}" in note and "not all labelled" in note


def test_a_read_only_working_directory_without_out_is_a_usage_error(in_tmp, capsys, monkeypatch):
    """Without --out the run writes runs/ (or results/) in the working directory: one that
    cannot be written there is refused in one line before any work, not an OSError later."""
    unwritable = in_tmp.resolve()
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: Path(p).resolve() != unwritable and real_access(p, mode)
    )
    for argv in (["--quick"], []):
        with pytest.raises(SystemExit) as exc:
            shapes.parse_args(argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert f"cannot write in {unwritable}" in err or "cannot write in ." in err, err
        assert "give --out DIR" in err
    assert list(in_tmp.iterdir()) == []
    assert shapes.parse_args(["--quick", "--out", str(in_tmp.parent / "elsewhere")]).quick


def test_the_distilled_translator_has_one_name(in_tmp):
    """ "distilled" in tables, plots and videos, and accepted by --methods; its key stays
    ccgan_sim, as the committed shapes.json files and stage folders have it."""
    assert methods.METHOD_NAMES["ccgan_sim"] == "distilled" == plots.LABELS["ccgan_sim"]
    assert report.METHOD_NAMES is methods.METHOD_NAMES
    cfg = shapes.parse_args(["--methods", "none", "distilled", "--robust-methods", "distilled"])
    assert cfg.methods == ("none", "ccgan_sim") and cfg.robust_methods == ("ccgan_sim",)
    help_text = shapes.build_parser().format_help()
    assert "--distilled-path" in help_text and "CCGAN-GP + sim" not in help_text


def test_unlabelled_translators_need_the_trust_flag(small_xml, tmp_path, monkeypatch):
    """The solid-disc arm's files record no labels: refused (here on the small arm, and from the
    command line on the I-Support arm) unless --trust-unlabelled-translators is given."""
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    cfg = _translator_run(small_xml, tmp_path, methods=("none", "ccgan"), ccgan_path=str(SHIPPED))
    with pytest.raises(methods.TranslatorError, match="--trust-unlabelled-translators"):
        pipeline.evaluate(cfg, command="test", log=lambda *_: None)
    assert not (tmp_path / "out").exists()
    trusted = dataclasses.replace(cfg, trust_unlabelled_translators=True)
    data = pipeline.evaluate(trusted, command="test", log=lambda *_: None)
    assert "ccgan" in data["methods_run"]
    argv = ["--methods", "none", "ccgan", "--ccgan-path", str(SHIPPED), "--shapes", "circle"]
    argv += ["--duration", "0.5", "--out", str(tmp_path / "cli")]
    with pytest.raises(SystemExit) as exc:
        shapes.main(argv)
    assert "does not record its method" in str(exc.value) and "solid" in str(exc.value)
    assert not (tmp_path / "cli").exists()
    assert shapes.parse_args([*argv, "--trust-unlabelled-translators"]).trust_unlabelled_translators


#: The translator methods the committed runs hold files of: the translator taught on the
#: identified arm (ccgan_ident, the chain's ident_sim stage) and the conditioned one over a range
#: of media (ccgan_range, studies/results/h200/media_range/range/ only) are in no committed run.
COMMITTED_METHODS = tuple(
    m for m in methods.TRANSLATOR_METHODS if m not in ("ccgan_ident", "ccgan_range")
)


@pytest.mark.parametrize(
    "run, target, paths",
    [
        ("rerun_2026-11-27/run", "constrained", {m: m for m in COMMITTED_METHODS}),
        # The rerun made no aged CCGAN-GP, only the distilled one.
        ("rerun_2026-11-27/run", "aged", {"ccgan_sim": "aged_sim"}),
        ("run", "constrained", {m: m for m in COMMITTED_METHODS}),
        ("run", "aged", {"ccgan": "aged", "ccgan_sim": "aged_sim"}),
    ],
)
def test_committed_translators_are_labelled_for_their_stage(run, target, paths):
    """Every committed I-Support translator says what it is, and loads as the chain's table
    stages give it (their --*-path and --target-domain), with no trust flag: the rerun's on
    models/softarm.xml (the defaults), the first run's on the previous arm."""
    from ccgan.translator import LINEAR_TRANSLATORS_DIR, TRANSLATORS_DIR

    run = ROOT / "results" / "paper" / run
    if run == LINEAR_TRANSLATORS_DIR:
        arm_hash = _file_hash(constants.LINEAR_LAW_MODEL_PATH)
    else:
        assert run == TRANSLATORS_DIR
        arm_hash = _file_hash(constants.DEFAULT_MODEL_PATH)
    given = {f"{m}_path": str(run / folder / "translator.ckpt") for m, folder in paths.items()}
    cfg = pipeline.EvalConfig(seeds=(0, 1, 2), target_domain=target, **given)
    for method in paths:
        tr, why = methods.load_translator(method, cfg)
        assert tr.model_hashes == {arm_hash} and sorted(tr.trained_seeds) == [0, 1, 2], why


def test_default_translators_are_refused_for_the_aged_arm(in_tmp):
    """The default translators translate into D_c, and the default run folder has no aged
    CCGAN-GP: --target-domain aged without paths stops before any work, naming the flag and
    both domains, never scoring D_c's translators on the aged arm."""
    for method in COMMITTED_METHODS:
        with pytest.raises(methods.TranslatorError) as exc:
            methods.load_translator(method, pipeline.EvalConfig(target_domain="aged"))
        message = str(exc.value)
        assert methods.PATH_FLAGS[method] in message and "--target-domain aged" in message
        assert "'aged'" in message and "'constrained'" in message
    argv = ["--target-domain", "aged", "--methods", "none", "ccgan_sim", "--shapes", "circle"]
    with pytest.raises(SystemExit) as exc:
        shapes.main([*argv, "--duration", "0.5", "--no-robustness", "--out", "out"])
    assert "--distilled-path" in str(exc.value.code) and not Path("out").exists()


def test_the_robustness_tests_leave_out_the_distilled_translator_unless_asked(in_tmp):
    """The main job scores ccgan_sim in its table, plots and videos but not in the noise and
    periodicity tests, which would take it past 20 min on 2 cores; --robust-methods adds it."""
    from eval import simulate

    every = ("none", "stretch", "ccgan", "ccgan_sim", "wcgan")
    default = dataclasses.replace(shapes.parse_args([]), methods=every)
    asked = dataclasses.replace(
        shapes.parse_args(["--robust-methods", "ccgan_sim", "stretch"]), methods=every
    )
    off = dataclasses.replace(shapes.parse_args(["--no-robustness"]), methods=every)

    def robust(cfg):
        plan = simulate.Plan(cfg, None, None, {}, list(every), 15, {}, {}, {}, None)
        return plan.robust_methods

    assert robust(default) == ["ccgan"]
    assert robust(asked) == ["ccgan_sim", "stretch"]
    assert robust(off) == []
