"""`mjx_arm.babble` with a medium off the pair: `--domain-file` and `BabbleConfig.domains`
holding a `Domain`, on a 3-segment model (CPU, small)."""

import mjx_arm  # noqa: I001  (before jax: it sets an XLA CPU flag)

import dataclasses

import numpy as np
import pytest

from mjx_arm import babble, dataset, domains
from mjx_arm.babble import cli as babble_cli
from mjx_arm.programs import babble_programs

CONFIG = babble.BabbleConfig(n_train=3, n_val=1, duration_s=2.0, chunk=2, backend="c")


@pytest.fixture(scope="module")
def xml():
    return mjx_arm.generate_xml(dataclasses.replace(mjx_arm.ArmParams(), n_segments=3))


def test_a_domain_file_babbles_a_medium_off_the_pair_in_its_own_stream(tmp_path, xml):
    """--domain-file: a medium of 5x D_s's drag, babbled under its own name, in the stream that
    name draws (`studies.identify_targets` babbles the same programs for its identification)."""
    model = tmp_path / "arm.xml"
    model.write_text(xml)
    medium = tmp_path / "half_drag.json"
    medium.write_text('{"domain": {"name": "half_drag", "viscosity_scale": 10.05845}}')
    argv = ["--domain", "source", "--domain-file", str(medium), "--n", "2", "--n-val", "1"]
    argv += ["--duration", "1", "--model", str(model), "--out", str(tmp_path / "out")]
    assert babble_cli.main([*argv, "--no-progress"]) == 0
    files = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert files == ["half_drag_train.npz", "half_drag_val.npz", "manifest.json"] + [
        "source_train.npz", "source_val.npz"
    ]  # fmt: skip
    half = dataset.load_dataset(tmp_path / "out" / "half_drag_train.npz")
    assert half.domain == "half_drag" and half.domain_fields["viscosity_scale"] == 10.05845
    config = dataclasses.replace(CONFIG, seed=0, duration_s=1.0)
    want = babble_programs(config, [0, 1], domain="half_drag", split="train")
    np.testing.assert_array_equal(half.pressures_bar, want)
    domain = mjx_arm.Domain(name="half_drag", viscosity_scale=10.05845)
    poses = mjx_arm.load(xml=xml, domain=domain).rollout(want, backend="c")
    np.testing.assert_allclose(half.poses, poses, atol=1e-5)  # that medium's arm, MuJoCo C
    src = dataset.load_dataset(tmp_path / "out" / "source_train.npz")
    np.testing.assert_array_equal(src.pose_low, half.pose_low)  # one shared normalisation
    assert not np.allclose(
        mjx_arm.load(xml=xml, domain="constrained").rollout(want, backend="c"), poses, atol=1e-4
    )  # not D_c's


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ('{"domain": {"viscosity_scale": 10}}', "name"),
        ('{"domain": {"name": "m", "drag": 10}}', "drag"),
        ("not json", "--domain-file"),
    ],
)
def test_a_bad_domain_file_is_a_usage_error(tmp_path, capsys, content, message):
    medium = tmp_path / "m.json"
    medium.write_text(content)
    with pytest.raises(SystemExit) as exit_:
        babble_cli.main(["--domain-file", str(medium), "--out", str(tmp_path / "out")])
    assert exit_.value.code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_a_domain_file_keeps_its_name_only_when_asked(tmp_path):
    medium = tmp_path / "m.json"
    medium.write_text('{"domain": {"name": "half_drag", "viscosity_scale": 10.05845}}')
    assert domains.read_domain_file(medium).domain.name == domains.IDENTIFIED
    kept = domains.read_domain_file(medium, keep_name=True).domain
    assert kept == mjx_arm.Domain(name="half_drag", viscosity_scale=10.05845)


def test_a_domain_of_a_built_in_name_must_be_that_medium():
    with pytest.raises(ValueError, match="its own name"):
        babble.BabbleConfig(domains=(mjx_arm.Domain(name="aged", stiffness_scale=0.5),))
    with pytest.raises(ValueError, match="distinct"):
        babble.BabbleConfig(domains=("source", mjx_arm.Domain(name="source")))
    with pytest.raises(ValueError, match="rod"):
        babble.BabbleConfig(domains=(mjx_arm.Domain(name="m"),), backend="rod")
