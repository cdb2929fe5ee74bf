"""Guards of the ccgan package: nothing overwritten, nothing mixed, no wrong answer with status 0.

Every bad option, data file or checkpoint must be refused before any work starts, with a message
naming what is wrong. The data files here are small synthetic `mjx_arm.dataset` files (no
simulation); the arm is the 3-segment test arm, loaded only for its model hash.
"""

import argparse
import dataclasses
import json
import signal

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mjx_arm
from ccgan import checkpoint, distill, load_translator, tune
from ccgan import cli as cli_lib
from ccgan import config as config_lib
from ccgan import data as data_lib
from ccgan import forward as forward_lib
from ccgan import train as train_lib
from ccgan import translator as translator_lib
from ccgan.models import Generator
from ccgan.translator import SOLID_TRANSLATORS_DIR, Translator, translator_path
from mjx_arm import constants
from mjx_arm.dataset import Dataset, DatasetError, ModelHashMismatchError, save_dataset
from mjx_arm.programs import random_held_programs
from tracking.config import ConfigError

# ----------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def small_arm(small_xml, tmp_path_factory):
    """(MJCF path, model hash) of the 3-segment arm."""
    path = tmp_path_factory.mktemp("arm") / "small.xml"
    path.write_text(small_xml)
    return str(path), mjx_arm.load(path).model_hash


def write_dataset(path, domain, model_hash, n=4, steps=20, seed=0, split="train"):
    """A synthetic babbling file: held random pressures, poses a smooth random walk."""
    rng = np.random.default_rng(seed)
    pressures = random_held_programs(rng, n, steps).astype(np.float32)
    poses = np.cumsum(rng.normal(scale=0.01, size=(n, steps, 6)), axis=1).astype(np.float32)
    low, high = poses.reshape(-1, 6).min(0), poses.reshape(-1, 6).max(0)
    save_dataset(
        path,
        Dataset(pressures, poses, low, high, domain, {}, model_hash, seed=seed, split=split),
    )
    return str(path)


@pytest.fixture
def files(tmp_path, small_arm):
    """Valid source and constrained files of the small arm: {name: path}."""
    _, h = small_arm
    return {
        "s": write_dataset(tmp_path / "s.npz", "source", h, seed=1),
        "s2": write_dataset(tmp_path / "s2.npz", "source", h, seed=2),
        "c": write_dataset(tmp_path / "c.npz", "constrained", h, seed=3),
    }


def usage_error(main, argv, capsys) -> str:
    """Runs a CLI that must stop with a usage error (status 2); returns its message (the usage
    lines above it list every flag, so they are cut off)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "error: " in err
    return err.split("error: ", 1)[1]


TINY_TRAIN = ["--epochs", "1", "--batch-size", "2", "--window-length", "5", "--n-val", "1"]
TINY_TRAIN += ["--forward-epochs", "1", "--gen-hidden", "4", "--gen-fc", "4"]
TINY_TRAIN += ["--k-choice", "forward"]  # the simulator's choice: tests/test_ccgan.py


# ----------------------------------------------------------------------------- data files


def test_dataset_files_must_belong_to_their_slot_and_one_arm(tmp_path, files):
    aged = write_dataset(tmp_path / "a.npz", "aged", "0" * 16, seed=4)
    # A constrained slot takes any non-source domain; files of one slot are concatenated.
    d_s, d_c = data_lib.read_translation_files([files["s"], files["s2"]], [files["c"]])
    assert d_s.pressures_bar.shape == (8, 20, 3) and d_c.domain == "constrained"
    assert d_s.model_hash == d_c.model_hash
    assert (d_s.bounds.low <= d_s.poses.reshape(-1, 6).min(0)).all()
    other_arm = write_dataset(tmp_path / "a_same_arm.npz", "aged", d_s.model_hash, seed=5)
    assert data_lib.read_domain([other_arm], "constrained").domain == "aged"

    # Source data passed as constrained data, and the other way round.
    with pytest.raises(DatasetError, match="non-source.*s2.npz \\(source\\)"):
        data_lib.read_translation_files([files["s"]], [files["s2"]])
    with pytest.raises(DatasetError, match="'source' data only.*c.npz \\(constrained\\)"):
        data_lib.read_translation_files([files["c"]], [files["c"]])
    # One slot mixing domains, or arms (model hashes: e.g. another segment count).
    with pytest.raises(DatasetError, match="mix domains"):
        data_lib.read_domain([files["c"], other_arm], "constrained")
    other_hash = write_dataset(tmp_path / "c0.npz", "constrained", "0" * 16, seed=6)
    with pytest.raises(DatasetError, match="segment count.*c0.npz \\(0000000000000000\\)"):
        data_lib.read_domain([files["c"], other_hash], "constrained")
    # Both slots from different arms.
    with pytest.raises(DatasetError, match="different arms.*s.npz.*a.npz"):
        data_lib.read_translation_files([files["s"]], [aged])
    # Programs of different lengths in one slot.
    longer = write_dataset(tmp_path / "long.npz", "source", d_s.model_hash, steps=30)
    with pytest.raises(DatasetError, match="program lengths.*long.npz \\(30\\)"):
        data_lib.read_domain([files["s"], longer])
    # The arm the caller names: both hashes in the message.
    with pytest.raises(ModelHashMismatchError, match=f"{d_s.model_hash}.*{'f' * 16}"):
        data_lib.read_domain([files["s"]], "source", model_hash="f" * 16)


def test_train_cli_refuses_mixed_or_wrong_arm_data(tmp_path, files, small_arm, capsys):
    model, model_hash = small_arm
    workdir = tmp_path / "run"
    base = ["--model", model, "--workdir", str(workdir), *TINY_TRAIN]
    # Source files passed as --constrained: named in the message.
    err = usage_error(
        train_lib.main, ["--source", files["s"], "--constrained", files["s2"], *base], capsys
    )
    assert "--constrained" in err and "s2.npz (source)" in err
    # Data of another arm than --model: both hashes named.
    other = write_dataset(tmp_path / "o.npz", "constrained", "e" * 16)
    err = usage_error(
        train_lib.main, ["--source", files["s"], "--constrained", other, *base], capsys
    )
    assert "e" * 16 in err and model_hash in err and "o.npz" in err
    # A truncated file: a clear message naming it, not a BadZipFile traceback.
    cut = tmp_path / "cut.npz"
    cut.write_bytes(open(files["c"], "rb").read()[:300])
    err = usage_error(
        train_lib.main, ["--source", files["s"], "--constrained", str(cut), *base], capsys
    )
    assert "cut.npz" in err and "Traceback" not in err
    # More held-out trajectories than there are: refused before training anything.
    argv = ["--source", files["s"], "--constrained", files["c"], *base, "--n-val", "9"]
    assert "n_val=9" in usage_error(train_lib.main, argv, capsys)
    assert not workdir.exists()


# ----------------------------------------------------------------------------- options


@pytest.mark.parametrize(
    "flags, named",
    [
        (["--epochs", "0"], "--epochs"),
        (["--epochs", "-1"], "--epochs"),
        (["--lr-generator", "-1"], "--lr-generator"),
        (["--lr-critic", "0"], "--lr-critic"),
        (["--batch-size", "0"], "--batch-size"),
        (["--window-length", "1"], "--window-length"),
        (["--hold-factors", "0", "5"], "--hold-factors"),
        (["--beta2", "1"], "--beta2"),
        (["--forward-epochs", "0"], "--forward-epochs"),
        (["--forward-lr", "nan"], "--forward-lr"),
        (["--seeds", "1", "1"], "--seeds"),
    ],
)
def test_train_cli_refuses_bad_options_before_any_work(tmp_path, files, flags, named, capsys):
    workdir = tmp_path / "run"
    argv = ["--source", files["s"], "--constrained", files["c"], "--workdir", str(workdir)]
    err = usage_error(train_lib.main, [*argv, *TINY_TRAIN, *flags], capsys)
    assert named in err
    assert not workdir.exists()  # nothing written: no untrained translator


def test_old_stretch_choices_name_still_reads():
    """The hold factors were `stretch_choices` once: old flags and stored configs still work."""
    parser = train_lib.build_parser()
    argv = ["--source", "s.npz", "--constrained", "c.npz", "--workdir", "w"]
    args = parser.parse_args([*argv, "--stretch-choices", "3", "4"])
    assert cli_lib.config_from_args(parser, args, config_lib.TrainConfig).hold_factors == (3, 4)
    assert "stretch-choices" not in parser.format_help()
    stored = config_lib.TrainConfig(hold_factors=(2, 7)).to_dict()
    stored["stretch_choices"] = stored.pop("hold_factors")
    assert config_lib.TrainConfig.from_dict(stored).hold_factors == (2, 7)


def test_run_stored_with_stretch_choices_resumes_under_hold_factors(tmp_path):
    config = config_lib.TrainConfig(hold_factors=(2, 7))
    meta = {"config": config.to_dict(), "data": "d", "seeds": [0]}
    old = meta | {"config": config_lib.stored_config(meta["config"])}
    old["config"]["stretch_choices"] = old["config"].pop("hold_factors")
    path = checkpoint.save(tmp_path / "state.ckpt", {"x": np.zeros(2)}, old)
    with pytest.raises(checkpoint.CheckpointError):
        checkpoint.load(path, expect=meta)
    checkpoint.load(path, expect=train_lib.resume_expectation(path, meta))


def test_committed_translator_config_reads_with_the_renamed_field():
    path = SOLID_TRANSLATORS_DIR / "ccgan" / "translator_seed0.ckpt"
    stored = checkpoint.read(path)[0]["config"]
    assert "stretch_choices" in stored
    config = config_lib.TrainConfig.from_dict(stored)
    assert config.hold_factors == tuple(stored["stretch_choices"])
    assert load_translator(path, trust_unlabelled=True).k in config.hold_factors


def test_train_cli_refuses_a_file_as_workdir(tmp_path, files, capsys):
    workdir = tmp_path / "run"
    workdir.write_text("my notes")
    argv = ["--source", files["s"], "--constrained", files["c"], "--workdir", str(workdir)]
    assert "--workdir" in usage_error(train_lib.main, [*argv, *TINY_TRAIN], capsys)
    assert workdir.read_text() == "my notes"


@pytest.mark.parametrize(
    "cls, kwargs, field",
    [
        (config_lib.TrainConfig, {"epochs": 0}, "epochs"),
        (config_lib.TrainConfig, {"lr_generator": -1.0}, "lr_generator"),
        (config_lib.TrainConfig, {"window_length": 1}, "window_length"),
        (config_lib.TrainConfig, {"batch_size": 0}, "batch_size"),
        (config_lib.TrainConfig, {"hold_factors": ()}, "hold_factors"),
        (config_lib.TrainConfig, {"lambda_cycle": float("inf")}, "lambda_cycle"),
        (config_lib.TrainConfig, {"feedback_impl": "fast"}, "feedback_impl"),
        (tune.SearchSpace, {"window_lengths": (1, 5)}, "window_lengths"),
        (tune.SearchSpace, {"lr_critic": (1e-3, 1e-5)}, "lr_critic"),
        (distill.DistillConfig, {"batch_size": 0}, "batch_size"),
        (distill.DistillConfig, {"epochs": 0}, "epochs"),
        (distill.DistillConfig, {"n_val": 0}, "n_val"),
        (distill.DistillConfig, {"learning_rate": -1e-3}, "learning_rate"),
    ],
)
def test_configs_refuse_unusable_values(cls, kwargs, field):
    with pytest.raises(ConfigError, match=f"^{field} ") as exc:
        cls(**kwargs)
    assert exc.value.field == field and isinstance(exc.value, ValueError)


def test_tuned_hyperparameters_still_trace():
    """`ccgan.tune` replaces learning rates by traced values inside jit: not checked there."""
    f = jax.jit(lambda lr: dataclasses.replace(config_lib.TrainConfig(), lr_generator=lr).epochs)
    assert f(jnp.float32(1e-3)) == 550


@pytest.fixture(scope="module")
def shipped():
    """The solid-disc arm's CCGAN-GP: its files record no arm, so it runs on the small arms."""
    return str(SOLID_TRANSLATORS_DIR / "ccgan" / "translator.ckpt")


@pytest.mark.parametrize(
    "main, flags, named",
    [
        (distill.main, ["--batch-size", "0"], "--batch-size"),
        (distill.main, ["--epochs", "0"], "--epochs"),
        (distill.main, ["--learning-rate", "0"], "--learning-rate"),
        (distill.main, ["--n-val", "0"], "--n-val"),
    ],
)
def test_stage_clis_refuse_bad_options_before_any_work(
    tmp_path, small_arm, shipped, main, flags, named, capsys
):
    out = tmp_path / "out"
    argv = ["--translators", shipped, "--out", str(out), "--model", small_arm[0], *flags]
    err = usage_error(main, argv, capsys)
    assert named in err
    assert not out.exists()  # no teacher cache, no translator


def test_stage_clis_refuse_bad_paths(tmp_path, small_arm, shipped, capsys):
    main = distill.main
    out = tmp_path / "out"
    base = ["--translators", shipped, "--out"]
    assert "--model" in usage_error(
        main, [*base, str(out), "--model", str(tmp_path / "none.xml")], capsys
    )
    (tmp_path / "file").write_text("")
    err = usage_error(main, [*base, str(tmp_path / "file"), "--model", small_arm[0]], capsys)
    assert "--out" in err
    garbage = tmp_path / "garbage.ckpt"
    garbage.write_bytes(np.random.default_rng(0).bytes(300))
    argv = ["--translators", str(garbage), "--out", str(out), "--model", small_arm[0]]
    err = usage_error(main, argv, capsys)
    assert "garbage.ckpt" in err and len(err) < 2000
    assert not out.exists()


def test_stages_simulate_the_arm_named_by_model(tmp_path, small_arm, shipped, capsys):
    """Default: the I-Support arm the committed translators were trained on; a translator
    labelled for another arm or domain is refused, an unlabelled one unless trusted."""
    p = distill.build_parser()
    assert p.parse_args(["--translators", "t", "--out", "o"]).model == str(
        constants.TRANSLATOR_MODEL_PATH
    )
    model, model_hash = small_arm
    argv = ["--translators", shipped, "--out", str(tmp_path / "o"), "--model", model]
    a = p.parse_args([*argv, "--trust-unlabelled-translators"])
    stage = distill.start_stage(p, a, "ccgan.distill", {}, [])
    assert stage.arm_c.model_hash == stage.arm_s.model_hash == model_hash
    assert stage.arm_c.domain.name == "constrained" and stage.arm_s.domain.name == "source"
    assert stage.run["model"] == model and stage.run["model_hash"] == model_hash
    assert stage.run["method"] == "distill"
    assert "--trust-unlabelled-translators" in usage_error(distill.main, argv, capsys)

    tree, meta = checkpoint.load(shipped)
    for name, labels, named in (
        ("other_arm", labelled("ccgan", "constrained", "d" * 16), ["d" * 16, model_hash]),
        ("other_domain", labelled("ccgan", "aged", model_hash), ["'aged'", "'constrained'"]),
    ):
        other = checkpoint.save(tmp_path / f"{name}.ckpt", tree, meta | labels)
        argv = ["--translators", str(other), "--out", str(tmp_path / "o2"), "--model", model]
        err = usage_error(distill.main, argv, capsys)
        assert all(n in err for n in named) and not (tmp_path / "o2").exists()

    # Another domain's translator only starts the stage when --start-domain names its domain;
    # the stage is still the --domain's (what it writes is labelled so: the test below).
    p = distill.build_parser()
    a = p.parse_args([*argv, "--start-domain", "aged"])
    stage = distill.start_stage(p, a, "ccgan.distill", {}, [])
    assert stage.arm_c.domain.name == "constrained"
    assert (stage.run["domain"], stage.run["start_domain"]) == ("constrained", "aged")
    err = usage_error(distill.main, [*argv, "--start-domain", "constrained"], capsys)
    assert "'aged'" in err and "--start-domain constrained" in err

    # A translator trained on the reference rod's data starts a stage only with
    # --start-rod-trained (issue 50's data-only translator for the rod), and that flag refuses a
    # file trained on any other arm.
    rod_hash = "rod-" + "e" * 16
    rod = checkpoint.save(
        tmp_path / "rod.ckpt", tree, meta | labelled("ccgan", "constrained", rod_hash)
    )
    argv = ["--translators", str(rod), "--out", str(tmp_path / "o3"), "--model", model]
    err = usage_error(distill.main, argv, capsys)
    assert "reference rod's data" in err and rod_hash in err
    a = p.parse_args([*argv, "--start-rod-trained"])
    stage = distill.start_stage(p, a, "ccgan.distill", {}, [])
    assert stage.run["start_rod_trained"] and stage.run["model_hash"] == model_hash
    chain_file = checkpoint.save(
        tmp_path / "chain.ckpt", tree, meta | labelled("ccgan", "constrained", model_hash)
    )
    argv = ["--translators", str(chain_file), "--out", str(tmp_path / "o4"), "--model", model]
    err = usage_error(distill.main, [*argv, "--start-rod-trained"], capsys)
    assert "not trained on the reference rod's data" in err and not (tmp_path / "o4").exists()


def labelled(method, target_domain, model_hash) -> dict:
    """A translator file's labels (`ccgan.translator.LABELS`)."""
    return {
        "method": method,
        "source_domain": "source",
        "target_domain": target_domain,
        "model_hash": model_hash,
    }


# ----------------------------------------------------------------------------- help


@pytest.mark.parametrize("module", [train_lib, tune, distill])
def test_every_option_has_help_and_a_shown_default(module):
    name = module.__name__
    p = module.build_parser()
    assert p.prog == f"python -m {name}"
    assert issubclass(p.formatter_class, argparse.ArgumentDefaultsHelpFormatter)
    for action in p._actions:
        assert action.help and action.help.strip(), f"{name}: {action.option_strings} has no help"
    text = p.format_help()
    assert f"usage: python -m {name}" in text and "(default: " in text
    if module is train_lib:
        assert "--epochs EPOCHS" in text and "(default: 550)" in text


# ----------------------------------------------------------------------------- progress


def _tiny_forward_setup(seed: int):
    """(data of 3 random 10-step programs per domain, a 2-epoch ForwardConfig of width 4)."""
    rng = np.random.default_rng(seed)
    arrays = []
    for _ in range(2):
        p = random_held_programs(rng, 3, 10)
        arrays += [p, np.cumsum(rng.normal(scale=0.01, size=(3, 10, 6)), axis=1)]
    data = data_lib.prepare(*arrays, window_length=5, n_val=1)
    return data, forward_lib.ForwardConfig(epochs=2, batch_size=2, hidden=4, fc=4)


def test_forward_training_shows_progress(tmp_path, capsys):
    """F_s and F_c train for minutes at the default settings: a bar says where it stands."""
    data, fconf = _tiny_forward_setup(seed=0)
    report = train_lib.train_forward_models(fconf, data, tmp_path, progress=True)
    err = capsys.readouterr().err
    assert "forward models" in err and "4/4" in err and "epoch" in err  # 2 models x 2 epochs
    assert set(report) == {"forward_s", "forward_c"} and (tmp_path / "forward_c.ckpt").exists()


def test_forward_training_stopped_during_f_c_keeps_f_s(tmp_path, monkeypatch):
    """A run stopped while F_c trains (a deadline) keeps F_s: the resumed run trains F_c only;
    other settings train both again."""
    data, fconf = _tiny_forward_setup(seed=1)
    real_train, trained = forward_lib.train_forward, []

    def train_then_stop_at_f_c(config, split, *args, **kwargs):
        if split is data.constrained and not trained:
            raise KeyboardInterrupt  # the stop, while F_c trains
        return real_train(config, split, *args, **kwargs)

    monkeypatch.setattr(forward_lib, "train_forward", train_then_stop_at_f_c)
    with pytest.raises(KeyboardInterrupt):
        train_lib.train_forward_models(fconf, data, tmp_path, progress=False)
    f_s = (tmp_path / "forward_s.ckpt").read_bytes()
    assert not (tmp_path / "forward_c.ckpt").exists()
    assert set(json.loads((tmp_path / "forward_metrics.json").read_text())) == {"forward_s"}

    def counting(config, split, *args, **kwargs):
        trained.append("forward_s" if split is data.source else "forward_c")
        return real_train(config, split, *args, **kwargs)

    monkeypatch.setattr(forward_lib, "train_forward", counting)
    report = train_lib.train_forward_models(fconf, data, tmp_path, progress=False, resume=True)
    assert trained == ["forward_c"] and (tmp_path / "forward_s.ckpt").read_bytes() == f_s
    assert set(report) == set(json.loads((tmp_path / "forward_metrics.json").read_text()))
    assert set(report) == {"forward_s", "forward_c"}
    trained.clear()
    other = dataclasses.replace(fconf, epochs=3)
    train_lib.train_forward_models(other, data, tmp_path, progress=False, resume=True)
    assert trained == ["forward_s", "forward_c"]


# ----------------------------------------------------------------------------- translator


@pytest.fixture(scope="module")
def tiny_translator():
    gen = Generator(hidden=4, fc=8)
    params = gen.init(jax.random.PRNGKey(0), jnp.zeros((1, 3, 9)))
    bounds = data_lib.PoseBounds(np.array([-0.1, -0.1, -0.25, -0.5, -0.5, -1.0]), np.ones(6))
    return Translator(params, k=2, bounds=bounds, generator=gen)


def _program(t=6):
    pressures = np.full((t, 3), 1.0)
    poses = np.tile([0.01, 0.0, -0.2, 0.0, 0.0, -1.0], (t, 1))
    return pressures, poses


def test_translate_refuses_nan_and_implausible_units(tiny_translator):
    p, x = _program()
    out, k = tiny_translator.translate(p, x)
    assert out.shape == (12, 3) and k == 2
    cases = []
    bad = p.copy()
    bad[3, 1] = np.nan
    cases.append((bad, x, "pressures have non-finite.*step 3"))
    bad = x.copy()
    bad[2, 0] = np.inf
    cases.append((p, bad, "poses have non-finite.*step 2"))
    cases.append((p * 100.0, x, "outside the plausible.*bar"))  # kPa
    cases.append((-p, x, "outside the plausible.*bar"))
    bad = x.copy()
    bad[:, :3] *= 1000.0  # millimetres
    cases.append((p, bad, "metres"))
    bad = x.copy()
    bad[:, 3:] *= 2.0
    cases.append((p, bad, "unit d3.*norm is 2"))
    cases.append((p[:0], x[:0], "empty"))
    for pressures, poses, match in cases:
        with pytest.raises(ValueError, match=match):
            tiny_translator.translate(pressures, poses)


# ----------------------------------------------------------------------------- checkpoints


def test_load_translator_paths(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="empty translator path"):
        load_translator("")
    monkeypatch.setenv("CCGAN_TRANSLATOR", "")  # an empty variable counts as unset
    assert translator_path() == translator_path(None) != translator_path("x")
    missing = tmp_path / "missing.ckpt"
    with pytest.raises(FileNotFoundError, match="missing.ckpt"):
        load_translator(missing)
    with pytest.raises(checkpoint.CheckpointError):  # still a CheckpointError too
        load_translator(missing)
    garbage = tmp_path / "random.ckpt"
    for seed in range(5):
        garbage.write_bytes(np.random.default_rng(seed).bytes(4000))
        with pytest.raises(checkpoint.CheckpointError, match="random.ckpt") as exc:
            load_translator(garbage)
        assert len(str(exc.value)) < 200 and "\\x" not in str(exc.value)


def test_changed_config_names_the_differing_fields(tmp_path):
    meta = {"config": {"epochs": 10, "lr": 1e-4, "nested": {"a": [1, 2]}}, "data": "abc"}
    path = checkpoint.save(tmp_path / "s.ckpt", {"x": np.zeros(2)}, meta)
    want = {"config": {"epochs": 10, "lr": 3e-4, "nested": {"a": [1, 3]}, "new": 1}}
    with pytest.raises(checkpoint.CheckpointError, match="does not match this run") as exc:
        checkpoint.load(path, expect=want)
    msg = str(exc.value)
    assert "config.lr: stored 0.0001, this run 0.0003" in msg
    assert "config.nested.a: stored [1, 2], this run [1, 3]" in msg
    assert "config.new: not stored, this run 1" in msg
    assert "epochs" not in msg  # unchanged fields are not listed


@pytest.mark.slow  # two forward trainings on this CPU: 69 s in CI (docs/testing.md)
def test_forward_models_trained_once_serve_other_runs_only_when_they_fit(
    tmp_path, files, small_arm, capsys
):
    model, h = small_arm
    data = ["--source", files["s"], "--constrained", files["c"], "--model", model, *TINY_TRAIN]
    forward_dir, run = tmp_path / "forward", tmp_path / "run"
    train_lib.main([*data, "--workdir", str(forward_dir), "--forward-only"])
    assert {p.name for p in forward_dir.iterdir()} == set(train_lib.FORWARD_FILES)
    # Other forward settings than those F_c was trained with: refused before any training.
    err = usage_error(
        train_lib.main,
        [*data, "--forward-hidden", "8", "--workdir", str(run), "--forward-from", str(forward_dir)],
        capsys,
    )
    assert "--forward-from" in err and "hidden" in err
    assert not (run / "forward_c.ckpt").exists()
    err = usage_error(
        train_lib.main, [*data, "--workdir", str(run), "--forward-from", str(tmp_path)], capsys
    )
    assert "forward_c.ckpt" in err
    train_lib.main([*data, "--workdir", str(run), "--forward-from", str(forward_dir)])
    copied = (run / "forward_c.ckpt").read_bytes()
    assert copied == (forward_dir / "forward_c.ckpt").read_bytes()
    # The first seed's model is stored once: translator.ckpt names translator_seed0.ckpt.
    assert (run / "translator.ckpt").resolve() == (run / "translator_seed0.ckpt").resolve()
    # Each file says what it is: the method, the data's domains and the arm.
    _, meta = checkpoint.load(run / "translator.ckpt")
    assert {k: meta[k] for k in translator_lib.LABELS} == labelled("ccgan", "constrained", h)


def test_f_c_on_its_own_data_and_windows_serves_only_runs_that_ask_for_them(
    tmp_path, files, small_arm, capsys
):
    """--forward-data / --forward-window / --forward-open-loop: F_c trains on other programs in
    longer windows, on its own predictions; a run that reuses it must name the same ones."""
    model, h = small_arm
    long_c = write_dataset(tmp_path / "long.npz", "constrained", h, n=3, steps=40, seed=7)
    data = ["--source", files["s"], "--constrained", files["c"], "--model", model, *TINY_TRAIN]
    own = ["--forward-data", str(long_c), "--forward-window", "20", "--forward-open-loop"]
    forward_dir = tmp_path / "forward"
    train_lib.main([*data, *own, "--workdir", str(forward_dir), "--forward-only"])
    _, meta = checkpoint.load(forward_dir / "forward_c.ckpt")
    assert meta["config"]["open_loop"] is True and "forward_windows" in meta
    metrics = json.loads((forward_dir / "forward_metrics.json").read_text())
    assert np.isfinite(metrics["forward_c"]["open_loop_cm"])  # on --constrained's held-out file
    # Without the same F_c data, the models do not fit this run: refused before training.
    err = usage_error(
        train_lib.main,
        [*data, "--forward-open-loop", "--workdir", str(tmp_path / "r1"),
         "--forward-from", str(forward_dir)],
        capsys,
    )  # fmt: skip
    assert "--forward-from" in err and "forward_windows" in err
    r2 = tmp_path / "r2"
    train_lib.main(
        [*data, *own, "--workdir", str(r2), "--forward-from", str(forward_dir), "--forward-only"]
    )
    assert (r2 / "forward_c.ckpt").read_bytes() == (forward_dir / "forward_c.ckpt").read_bytes()
    # F_c data of another domain, or windows longer than the programs: usage errors.
    aged = write_dataset(tmp_path / "aged.npz", "aged", h, seed=8)
    err = usage_error(
        train_lib.main, [*data, "--forward-data", str(aged), "--workdir", str(tmp_path / "r3")],
        capsys,
    )  # fmt: skip
    assert "--forward-data" in err and "aged" in err
    err = usage_error(
        train_lib.main, [*data, "--forward-window", "999", "--workdir", str(tmp_path / "r4")],
        capsys,
    )  # fmt: skip
    assert "--forward-window" in err


@pytest.mark.slow  # about 2 min on 2 cores (docs/testing.md)
def test_sigterm_stops_training_after_its_epoch_with_a_checkpoint(
    tmp_path, files, small_arm, monkeypatch
):
    """SIGTERM (a time limit, the chain's deadline) as training starts: one epoch, a checkpoint,
    no translator, exit status 143; the same command then finishes the run."""
    model, _ = small_arm
    data = ["--source", files["s"], "--constrained", files["c"], "--model", model, *TINY_TRAIN]
    argv = [*data, "--epochs", "3", "--workdir", str(tmp_path / "run")]  # the last --epochs wins

    def signal_at_once(signum, handler):
        assert signum == signal.SIGTERM
        handler(signum, None)  # as if the signal came the moment the handler was set

    with monkeypatch.context() as patch:
        patch.setattr(train_lib.signal, "signal", signal_at_once)
        with pytest.raises(SystemExit) as stopped:
            train_lib.main(argv)
    assert stopped.value.code == 128 + signal.SIGTERM
    _, meta = checkpoint.load(tmp_path / "run" / "state.ckpt")
    assert meta["epoch"] == 1 and not (tmp_path / "run" / "translator.ckpt").exists()
    train_lib.main(argv)
    assert (tmp_path / "run" / "translator.ckpt").exists()


def test_first_seed_link_replaces_a_copy_and_follows_the_seed(tmp_path):
    (tmp_path / "translator_seed3.ckpt").write_bytes(b"seed 3")
    (tmp_path / "translator.ckpt").write_bytes(b"an old copy")
    checkpoint.link_first_seed(tmp_path, "translator_seed3.ckpt")
    assert (tmp_path / "translator.ckpt").read_bytes() == b"seed 3"
    (tmp_path / "translator_seed3.ckpt").write_bytes(b"seed 3, rewritten")
    assert (tmp_path / "translator.ckpt").read_bytes() == b"seed 3, rewritten"
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "translator.ckpt",
        "translator_seed3.ckpt",
    ]


# ----------------------------------------------------------------------------- splits


def test_training_refuses_validation_files_as_training_data_and_vice_versa(
    tmp_path, files, small_arm, capsys
):
    """Files are concatenated and the last --n-val trajectories held out: a validation-split
    file must come last and be what is held out; a training-split one must not be held out."""
    model, h = small_arm
    val = {
        slot: write_dataset(tmp_path / f"{slot}_val.npz", domain, h, n=2, seed=5, split="val")
        for slot, domain in (("s", "source"), ("c", "constrained"))
    }
    out = tmp_path / "run"
    tiny = [*TINY_TRAIN, "--model", model, "--workdir", str(out), "--forward-only"]
    for source, n_val, named in (
        ([val["s"]], "2", "only validation-split"),  # the val file alone as training data
        ([val["s"], files["s"]], "2", "comes before"),  # val first: trained on, train held out
        ([files["s"], val["s"]], "3", "--n-val 2"),  # a training trajectory held out
    ):
        argv = ["--source", *source, "--constrained", files["c"], val["c"], *tiny, "--n-val", n_val]
        err = usage_error(train_lib.main, argv, capsys)
        assert "--source" in err and named in err and "val.npz (val)" in err
        assert not out.exists()
    argv = ["--source", val["s"], "--constrained", files["c"], "--n-trials", "1"]
    argv += ["--storage", str(tmp_path / "t.db"), "--report-dir", str(tmp_path / "r")]
    assert "only validation-split" in usage_error(tune.main, argv, capsys)
    # Train then val, the whole val file held out: accepted, with no note.
    d_s, d_c = data_lib.read_translation_files([files["s"], val["s"]], [files["c"], val["c"]])
    assert data_lib.check_slot_splits(2, d_s, d_c) == []
    assert d_s.splits == (("train", 4), ("val", 2))
    # More validation trajectories than held out: they are trained on, and a note says so.
    notes = data_lib.check_slot_splits(1, d_s, d_c)
    assert len(notes) == 2 and notes[0].startswith("--source")
    assert "the other 1 are trained on" in notes[0] and "--n-val 2" in notes[0]
    # Training files alone: their last --n-val trajectories are held out, as before.
    only_train = data_lib.read_translation_files([files["s"]], [files["c"]])
    assert data_lib.check_slot_splits(3, *only_train) == []


def test_training_refuses_held_out_trajectories_it_trains_on(tmp_path, files, small_arm, capsys):
    """Splits are checked by content, not by name or split: a file listed twice, a training file
    copied as the validation file, or one trajectory in both sets is refused before any work."""
    from mjx_arm.dataset import load_dataset

    model, h = small_arm
    s = load_dataset(files["s"])
    copy_as_val = write_dataset(tmp_path / "s_val.npz", "source", h, seed=1, split="val")
    # A validation file whose first trajectory is trajectory 2 of the training file.
    mixed = tmp_path / "mixed_val.npz"
    other = load_dataset(files["s2"])
    pressures = np.stack([s.pressures_bar[2], other.pressures_bar[0]])
    poses = np.stack([s.poses[2], other.poses[0]])
    low, high = poses.reshape(-1, 6).min(0), poses.reshape(-1, 6).max(0)
    save_dataset(mixed, Dataset(pressures, poses, low, high, "source", {}, h, seed=9, split="val"))
    out = tmp_path / "run"
    tiny = [*TINY_TRAIN, "--model", model, "--workdir", str(out), "--forward-only"]
    for source, n_val, named in (
        ([files["s"], files["s"]], "1", ["s.npz and", "s.npz hold the same data"]),
        ([files["s"], copy_as_val], "4", ["s.npz and", "s_val.npz hold the same data"]),
        ([files["s"], str(mixed)], "2", ["mixed_val.npz[0] is also trained on", "s.npz[2]"]),
    ):
        argv = ["--source", *source, "--constrained", files["c"], *tiny, "--n-val", n_val]
        err = usage_error(train_lib.main, argv, capsys)
        assert err.startswith("--source") and all(n in err for n in named), err
        assert len(err.strip().splitlines()) == 1 and not out.exists()
    # The constrained slot, through ccgan.tune too.
    argv = ["--source", files["s"], "--constrained", files["c"], files["c"], "--n-trials", "1"]
    argv += ["--storage", str(tmp_path / "t.db"), "--report-dir", str(tmp_path / "r")]
    err = usage_error(tune.main, argv, capsys)
    assert err.startswith("--constrained") and "hold the same data" in err
    assert not (tmp_path / "r").exists()
    # F_c trained on --forward-data is scored on the held-out D_c programs: none of them there.
    argv = ["--source", files["s"], "--constrained", files["c"], *tiny, "--n-val", "1"]
    err = usage_error(train_lib.main, [*argv, "--forward-data", files["c"]], capsys)
    assert err.startswith("--forward-data: held-out trajectory") and "c.npz[3]" in err
    assert not out.exists()
    # By content alone: the same arrays under another name and split are refused in the library.
    d_s, d_c = data_lib.read_translation_files([files["s"], copy_as_val], [files["c"]])
    with pytest.raises(DatasetError, match="hold the same data"):
        data_lib.check_slot_splits(4, d_s, d_c)
    # Distinct files, the last 4 trajectories held out: accepted.
    d_s, _ = data_lib.read_translation_files([files["s"], files["s2"]], [files["c"]])
    assert data_lib.check_slot_splits(4, d_s, d_c) == []


# ----------------------------------------------------------------------------- translator labels

#: The committed CCGAN-GP of the I-Support arm (labelled, with F_c).
COMMITTED = translator_lib.TRANSLATORS_DIR / "ccgan" / "translator.ckpt"


def test_the_default_translator_is_of_the_default_arm(monkeypatch):
    """`load_translator()` with no path reads the chain's rerun on models/softarm.xml: a CCGAN-GP
    into D_c whose recorded arm is that file's `Arm.model_hash`, the arm the stages default to."""
    monkeypatch.delenv("CCGAN_TRANSLATOR", raising=False)
    assert translator_path() == COMMITTED
    # The arm `mjx_arm.load()` gives with no path, and the one the stages simulate by default.
    arm_hash = mjx_arm.load().model_hash
    assert mjx_arm.load(constants.TRANSLATOR_MODEL_PATH).model_hash == arm_hash
    meta, _ = checkpoint.read(translator_path())
    assert translator_lib.translator_labels(meta) == labelled("ccgan", "constrained", arm_hash)
    default = load_translator(model_hash=arm_hash, method="ccgan", target_domain="constrained")
    assert default.k >= 1
    # The previous arm's run is kept beside it, labelled for its own arm.
    old, _ = checkpoint.read(translator_lib.LINEAR_TRANSLATORS_DIR / "ccgan" / "translator.ckpt")
    assert old["model_hash"] == mjx_arm.load(constants.LINEAR_LAW_MODEL_PATH).model_hash
    assert old["model_hash"] != arm_hash


def test_load_translator_refuses_what_it_was_not_told_to_expect(tmp_path):
    """`load_translator(..., method=, target_domain=, model_hash=)`: another method, domain or
    arm is refused naming both values; an unlabelled file only with trust_unlabelled."""
    arm_hash = checkpoint.read(COMMITTED)[0]["model_hash"]
    good = load_translator(
        COMMITTED, method="ccgan", source_domain="source", target_domain="constrained"
    )
    assert good.k >= 1 and load_translator(COMMITTED, model_hash=arm_hash).k == good.k
    for kwargs, named in (
        ({"target_domain": "aged"}, ["'aged'", "'constrained'"]),
        ({"method": "wcgan"}, ["'wcgan'", "'ccgan'"]),
        ({"method": ("distill", "finetune")}, ["'distill' or 'finetune'", "'ccgan'"]),
        ({"model_hash": "e" * 16}, ["e" * 16, arm_hash]),
    ):
        with pytest.raises(translator_lib.TranslatorMismatchError) as exc:
            load_translator(COMMITTED, **kwargs)
        assert all(n in str(exc.value) for n in named) and "translator.ckpt" in str(exc.value)
    solid = SOLID_TRANSLATORS_DIR / "wcgan" / "translator.ckpt"
    with pytest.raises(translator_lib.UnlabelledTranslatorError, match="trust_unlabelled"):
        load_translator(solid)
    assert load_translator(solid, trust_unlabelled=True, method="ccgan").k >= 1
    # A label the file does record is checked even when trusted.
    tree, meta = checkpoint.load(solid)
    part = checkpoint.save(tmp_path / "part.ckpt", tree, meta | {"target_domain": "aged"})
    with pytest.raises(translator_lib.TranslatorMismatchError, match="'aged'"):
        load_translator(part, trust_unlabelled=True, target_domain="constrained")


def test_rewrite_meta_keeps_the_payload(tmp_path):
    path = checkpoint.save(tmp_path / "t.ckpt", {"w": np.arange(5.0)}, {"k": 5})
    before = path.read_bytes()
    out = checkpoint.rewrite_meta(path, {"method": "ccgan"})
    assert out["meta"] == {"k": 5, "method": "ccgan"} and path.read_bytes() != before
    tree, meta = checkpoint.load(path)
    np.testing.assert_array_equal(tree["w"], np.arange(5.0))
    assert meta == {"k": 5, "method": "ccgan"} and list(tmp_path.iterdir()) == [path]


def test_fine_tune_stages_label_what_they_write(tmp_path):
    """A distilled file is labelled as the stage's: its method, domain and arm."""
    from ccgan.stage import Stage

    tree, meta = checkpoint.load(COMMITTED)
    run = {"method": "distill", "domain": "aged", "model_hash": "a" * 16}
    stage = Stage([0], [(tree, meta)], [], None, None, tmp_path, run)
    stage.write([tree["g_c"]], [{}], {}, "distill.json")
    _, out = checkpoint.load(tmp_path / "translator.ckpt")
    assert {k: out[k] for k in translator_lib.LABELS} == labelled("distill", "aged", "a" * 16)
    assert out["finetune"]["method"] == "distill"


def test_predict_poses_refuses_nan_and_kpa():
    tr = load_translator(COMMITTED)
    pose0 = np.array([0.0, 0.0, -0.2, 0.0, 0.0, 1.0])
    commands = np.full((4, 3), 1.0)
    assert tr.predict_poses(commands, pose0).shape == (4, 6)
    for bad, match in (
        (np.where(np.eye(4, 3), np.nan, 1.0), "non-finite"),
        (commands * 100.0, "kPa"),
        (commands[:, :2], r"\[T, 3\]"),
    ):
        with pytest.raises(ValueError, match=match):
            tr.predict_poses(bad, pose0)
    with pytest.raises(ValueError, match="pose0"):
        tr.predict_poses(commands, np.full(6, np.nan))


def test_train_cli_stopped_by_patience_ends_as_finished(tmp_path, files, small_arm, monkeypatch):
    """A run that --patience ends early is finished, not stopped: exit status 0 (the chain
    would otherwise call it again and again), its best translators written."""
    from ccgan.sim_choice import Choice, SimulatorChoice

    script = iter([[9.0], [2.0], [3.0], [4.0], [5.0], [6.0], [7.0]])  # best after epoch 1

    def scripted(self, g_c_params):
        error = np.asarray(next(script))
        return Choice(k=np.array([1]), error_cm=error, errors_cm=np.repeat(error[:, None], 2, 1))

    monkeypatch.setattr(SimulatorChoice, "choose", scripted)
    model, _ = small_arm
    argv = ["--source", files["s"], "--constrained", files["c"], "--model", model]
    argv += [*TINY_TRAIN[:-2], "--k-choice", "simulator", "--k-choice-seconds", "0"]
    argv[argv.index("--epochs") + 1] = "6"
    argv += ["--stretch-every", "1", "--patience", "1", "--hold-factors", "1", "2"]
    argv += ["--workdir", str(tmp_path / "run")]
    train_lib.main(argv)  # no SystemExit
    rows = train_lib.read_rows(tmp_path / "run" / "k_choices.csv")
    assert [r["epoch"] for r in rows] == [0, 1, 2]
    assert (tmp_path / "run" / "translator_seed0.ckpt").is_file()
