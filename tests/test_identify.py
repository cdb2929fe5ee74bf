"""Identification of a target arm's medium and stiffness (`mjx_arm.identify`), on the 3-segment
arm: the JAX domain family against `mjx_arm.load`, recovery of known values from synthetic data,
bad inputs refused before any simulation, and the command line."""

import mjx_arm  # noqa: I001  (before jax: it sets an XLA CPU flag)

import dataclasses
import json
import math

import numpy as np
import pytest

from mjx_arm import babble, identify
from mjx_arm.identify_family import DomainFamily
from mjx_arm.programs import babble_programs

#: A target unlike the base ("constrained": the 3-segment model's fitted viscosity, stiffness 1).
TRUTH = mjx_arm.Domain(name="target", viscosity_scale=12.0, stiffness_scale=0.8)


@pytest.fixture(scope="module")
def xml():
    return mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))


@pytest.fixture(scope="module")
def data(xml):
    """4 babbling programs of 3 s [4, 30, 3] (bar) and the target's poses [4, 30, 6]."""
    config = babble.BabbleConfig(duration_s=3.0)
    programs = babble_programs(config, np.arange(4), domain="constrained", split="train")
    poses = mjx_arm.load(xml=xml, domain=TRUTH).rollout(programs, backend="c")
    return programs, poses


@pytest.mark.parametrize("substeps", [None, 5])
def test_family_builds_the_model_load_builds(xml, substeps):
    base = mjx_arm.load(xml=xml, domain="constrained", substeps=substeps)
    family = DomainFamily.of(base)
    for viscosity, stiffness in [(7.0, 0.6), (40.0, 1.3)]:
        theta = np.log([viscosity, stiffness])
        domain = mjx_arm.Domain(viscosity_scale=viscosity, stiffness_scale=stiffness)
        want = mjx_arm.load(xml=xml, domain=domain, substeps=substeps)
        got = family.model(theta)
        ref = want.mjx_model
        # The automatic inertia scale moves with the drag, so masses and gravity change too.
        assert want.inertia_scale != pytest.approx(base.inertia_scale, rel=0.1)
        for field in ("body_mass", "body_inertia", "body_subtreemass", "dof_armature"):
            np.testing.assert_allclose(getattr(got, field), getattr(ref, field), rtol=1e-5)
        for field in ("jnt_stiffness", "actuator_gainprm"):
            np.testing.assert_allclose(getattr(got, field), getattr(ref, field), rtol=1e-5)
        np.testing.assert_allclose(got.opt.viscosity, ref.opt.viscosity, rtol=1e-5)
        np.testing.assert_allclose(got.opt.gravity, ref.opt.gravity, rtol=1e-5)
        np.testing.assert_allclose(family.rest_qpos(theta), want.rest_qpos, atol=1e-6)
        stretch = family.controls(theta).stretch_per_bar
        assert stretch == pytest.approx(want.chamber_controls.stretch_per_bar, rel=1e-5)
        assert family.domain(theta).viscosity_scale == pytest.approx(viscosity)
    assert family.check_rest() < 1e-6


def test_search_recovers_viscosity_and_stiffness(xml, data):
    result = identify.identify(*data, xml=xml, method="search", n_val=1, progress=False)
    # Measured: 12.000 and 0.8000 (errors under 1e-4) in ~5 s; the base starts 68% and 25% off.
    assert result.values["viscosity_scale"] == pytest.approx(12.0, rel=2e-3)
    assert result.values["stiffness_scale"] == pytest.approx(0.8, rel=2e-3)
    assert result.domain.viscosity_scale == pytest.approx(result.values["viscosity_scale"])
    assert result.val_rms_cm < 0.01 < result.base_val_rms_cm
    assert all(0 <= u < 0.01 * result.values[k] for k, u in result.uncertainty.items())
    assert result.history[-1]["rms_mm"] < 0.05 < result.history[0]["rms_mm"]
    assert (result.n_train, result.n_val, result.duration_s) == (3, 1, 3.0)
    assert 5 < result.length_m * 100 < 40 and result.wall_s > 0
    json.dumps(result.to_dict())


def test_search_fits_one_field_and_keeps_the_other(xml, data):
    programs, _ = data
    softer = mjx_arm.Domain(viscosity_scale=12.0, stiffness_scale=0.6)
    poses = mjx_arm.load(xml=xml, domain=softer).rollout(programs, backend="c")
    base = mjx_arm.Domain(name="known medium", viscosity_scale=12.0)
    result = identify.identify(
        programs, poses, base=base, fit=("stiffness_scale",), xml=xml, n_val=1, progress=False
    )
    assert list(result.values) == ["stiffness_scale"]
    assert result.values["stiffness_scale"] == pytest.approx(0.6, rel=2e-3)
    assert result.domain.viscosity_scale == 12.0


def test_bad_inputs_are_refused_before_any_simulation(xml, data, monkeypatch):
    programs, poses = data

    def no_work(*args, **kwargs):
        raise AssertionError("an arm was loaded before the inputs were checked")

    monkeypatch.setattr(identify.arm_lib, "load", no_work)
    bad = [
        ((programs, poses[:, :-1]), {}, ValueError, "poses must be"),
        ((programs[0], poses[0]), {}, ValueError, r"\[N, T, 3\]"),
        ((programs[:1], poses[:1]), {}, ValueError, ">= 2 programs"),
        ((programs, np.where(poses > 0, np.nan, poses)), {}, ValueError, "non-finite"),
        ((programs.astype(bool), poses), {}, TypeError, "real numbers"),
        ((programs, poses), {"n_val": 4}, ValueError, "n_val must be in"),
        ((programs, poses), {"n_val": 0}, ValueError, "n_val must be in"),
        ((programs, poses), {"n_val": True}, TypeError, "n_val must be an int"),
        ((programs, poses), {"seeds": 0}, ValueError, "seeds must be"),
        ((programs, poses), {"method": "adam"}, ValueError, "method must be"),
        ((programs, poses), {"fit": ("mass_scale",)}, ValueError, "fit must name"),
        ((programs, poses), {"fit": ()}, ValueError, "fit must name"),
        ((programs, poses), {"config": identify.GradientConfig()}, TypeError, "SearchConfig"),
        ((programs, poses), {"config": identify.SearchConfig(span=1.0)}, ValueError, "span"),
        ((programs, poses), {"base": "nowhere"}, ValueError, "unknown domain"),
    ]
    for args, kwargs, error, match in bad:
        with pytest.raises(error, match=match):
            identify.identify(*args, xml=xml, progress=False, **kwargs)


def test_gauss_newton_steps_solve_a_linear_fit_and_bootstrap_it():
    # Residuals r_i = a_i - x (one parameter): J_i = -1, so the full step is mean(a) - x and a
    # bootstrap resample's step is its own mean minus x.
    a = np.array([1.0, 2.0, 4.0])
    residuals, jacobian = (a - 0.5)[:, None], -np.ones((3, 1, 1))
    full = identify.gauss_newton_steps(residuals, jacobian, np.ones((1, 3)))
    assert full[0, 0] == pytest.approx(7 / 3 - 0.5)
    weights = identify.bootstrap_weights(3, 500)
    steps = identify.gauss_newton_steps(residuals, jacobian, weights)
    np.testing.assert_allclose(steps[:, 0], weights @ a / 3 - 0.5)
    assert steps.std() == pytest.approx(np.std(a) / math.sqrt(3), rel=0.15)


@pytest.fixture(scope="module")
def babble_folder(xml, tmp_path_factory):
    """A 3-segment arm's MJCF file and a babbling folder of its aged domain (3 + 1 x 3 s)."""
    root = tmp_path_factory.mktemp("identify")
    model = root / "small.xml"
    model.write_text(xml)
    config = babble.BabbleConfig(
        n_train=3, n_val=1, duration_s=3.0, domains=("aged",), backend="c", chunk=4
    )
    babble.run(config, root / "babble", model_path=model, progress=False)
    return model, root / "babble"


def test_command_line_writes_the_report_beside_the_truth(babble_folder, tmp_path):
    model, folder = babble_folder
    args = ["--data", str(folder), "--out", str(tmp_path / "out"), "--model", str(model)]
    identify.main([*args, "--fit", "stiffness_scale", "--no-progress"])
    report = json.loads((tmp_path / "out" / "identify.json").read_text())
    assert report["truth"] == {"stiffness_scale": 0.7}
    result = report["results"]["search"]
    assert abs(result["error_pct"]["stiffness_scale"]) < 0.2
    assert (report["data"]["n_train"], report["data"]["n_val"]) == (3, 1)
    assert report["data"]["val"].endswith("aged_val.npz")
    table = (tmp_path / "out" / "identify.md").read_text()
    assert "| search | stiffness_scale | 1 | 0.7" in table and "--fit stiffness_scale" in table


def test_command_line_refuses_bad_options(babble_folder, tmp_path, capsys):
    model, folder = babble_folder
    out = ["--out", str(tmp_path / "out"), "--model", str(model)]
    a_file = tmp_path / "file"
    a_file.write_text("")
    bad = [
        (["--data", str(tmp_path / "none"), *out], "no such file or folder"),
        (["--data", str(folder), *out, "--domain", "source"], "holds no source_train.npz"),
        (["--data", str(folder), *out, "--n-programs", "9"], "holds 3"),
        (["--data", str(folder), *out, "--n-val", "2"], "holds 1 programs"),
        (["--data", str(folder), *out, "--fit", "mass"], "fit must name"),
        (["--data", str(folder), *out, "--method", "adam"], "invalid choice"),
        (["--data", str(folder), *out, "--seeds", "0"], "must be >= 1"),
        (["--data", str(folder), "--out", str(a_file / "x"), "--model", str(model)], "--out"),
        (["--data", str(folder), "--out", str(tmp_path / "o")], "made with model"),
    ]
    for argv, match in bad:
        with pytest.raises(SystemExit) as stop:
            identify.main(argv)
        assert stop.value.code == 2
        assert match in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_gradient_recovers_viscosity_and_stiffness(xml, data):
    # The 3-segment arm feels a longer step (5 substeps bias its fit by ~4%), so it fits in its
    # own timestep; 2 x 12 Adam steps and the Gauss-Newton polish. Measured: 12.02 and 0.804.
    config = identify.GradientConfig(substeps=0, chunk_periods=10, windows_s=(1.5, 3.0))
    result = identify.identify(
        *data, xml=xml, method="gradient", n_val=1, config=config, progress=False
    )
    assert result.values["viscosity_scale"] == pytest.approx(12.0, rel=0.01)
    assert result.values["stiffness_scale"] == pytest.approx(0.8, rel=0.01)
    assert result.val_rms_cm < 0.1 * result.base_val_rms_cm
    windows = {h.get("window_s") for h in result.history if "window_s" in h}
    assert windows == {2.0, 3.0}  # 1.5 s rounds up to whole chunks (10 periods, 1 s)


def test_a_medium_of_its_own_values_is_identified_beside_its_truth(xml, tmp_path):
    """A medium that is no built-in domain (studies.identify_targets' half and double drag):
    its babbling's metadata carries the Domain's values, identify.md prints them as the truth."""
    from mjx_arm import dataset
    from studies import identify_targets

    model = tmp_path / "small.xml"
    model.write_text(xml)
    dc = identify_targets.dc_viscosity_scale(str(model))
    unit = mjx_arm.load(xml=xml, domain=mjx_arm.Domain(viscosity_scale=1.0)).mj_model
    constrained = mjx_arm.load(xml=xml, domain="constrained").mj_model
    assert dc == pytest.approx(constrained.opt.viscosity / unit.opt.viscosity)
    domain = identify_targets.medium_domain("double_drag", str(model))
    assert (domain.viscosity_scale, domain.stiffness_scale) == (pytest.approx(2 * dc), 1.0)
    made = identify_targets.babble_medium(domain, 3, 1, 3.0, str(model))
    assert sorted(made) == ["double_drag_train.npz", "double_drag_val.npz"]
    dataset.save_folder(tmp_path / "babble", made)
    out = tmp_path / "out"
    argv = ["--data", str(tmp_path / "babble"), "--out", str(out), "--model", str(model)]
    identify.main([*argv, "--fit", "viscosity_scale", "--no-progress"])
    report = json.loads((out / "identify.json").read_text())
    assert report["truth"] == {"viscosity_scale": pytest.approx(2 * dc)}
    assert abs(report["results"]["search"]["error_pct"]["viscosity_scale"]) < 0.1
    table = (out / "identify.md").read_text()
    assert f"the data's domain, double_drag (viscosity_scale {2 * dc:.5g})" in table


def test_command_line_takes_the_rods_data(xml, tmp_path):
    """A file of the rod's model hash (here chain poses under that label, 6 s programs) is
    fitted with no truth: the rod is not a chain Domain."""
    from mjx_arm import dataset

    model = tmp_path / "small.xml"
    model.write_text(xml)
    config = babble.BabbleConfig(duration_s=6.0)
    programs = babble_programs(config, np.arange(3), domain="constrained", split="train")
    poses = mjx_arm.load(xml=xml, domain=TRUTH).rollout(programs, backend="c")
    ds = dataset.Dataset(
        pressures_bar=programs,
        poses=poses,
        pose_low=poses.min((0, 1)),
        pose_high=poses.max((0, 1)),
        domain="constrained",
        domain_fields=dataclasses.asdict(mjx_arm.Domain(name="constrained", viscosity_scale=None)),
        model_hash="rod-0123456789abcdef",
        seed=0,
        config={"backend": "rod"},
    )
    dataset.save_dataset(tmp_path / "constrained_train.npz", ds)
    out = tmp_path / "out"
    argv = ["--data", str(tmp_path / "constrained_train.npz"), "--out", str(out)]
    identify.main([*argv, "--model", str(model), "--fit", "viscosity_scale", "--no-progress"])
    report = json.loads((out / "identify.json").read_text())
    assert report["truth"] is None and report["data"]["duration_s"] == 6.0
    assert report["results"]["search"]["values"]["viscosity_scale"] > 0
    assert "Truth: unknown" in (out / "identify.md").read_text()


def test_targets_study_refuses_a_rod_case_without_its_data(tmp_path, capsys):
    from studies import identify_targets

    for argv, match in [
        (["--case", "rod"], "--case rod needs --rod-data"),
        (["--case", "rod", "--rod-data", str(tmp_path / "none")], "no such file or folder"),
        (["--case", "kite"], "invalid choice"),
    ]:
        with pytest.raises(SystemExit) as stop:
            identify_targets.main(["--out", str(tmp_path / "out"), *argv])
        assert stop.value.code == 2
        assert match in capsys.readouterr().err
    assert not (tmp_path / "out").exists()
