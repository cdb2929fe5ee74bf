"""Tests of ccgan.distill's source simulator: the D_s poses a teacher tracks come from the chain
or from the reference rod, and a teacher cache made from one is not reused for the other."""

import json

import numpy as np
import pytest

import mjx_arm
from ccgan.distill import DistillConfig
from ccgan.distill.teacher import source_poses, teacher_cache_key
from tracking.config import ConfigError


def test_an_unknown_source_simulator_is_refused_by_name():
    with pytest.raises(ConfigError, match="source_simulator"):
        DistillConfig(source_simulator="pyelastica")


def test_the_rods_targets_have_their_own_cache_key_and_the_chains_keep_theirs(small_xml):
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    chain = DistillConfig()
    rod = DistillConfig(source_simulator="rod")
    assert "source_simulator" not in json.loads(teacher_cache_key(chain, 15, arm_c))
    assert json.loads(teacher_cache_key(rod, 15, arm_c))["source_simulator"] == "rod"


def test_the_rods_targets_are_the_rods_d_s_path_not_the_chains(small_xml):
    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    programs = np.zeros((2, 8, 3))
    programs[:, 2:, 0] = 2.0  # chamber 0 to 2 bar after 0.2 s: the tip bends away from rest
    programs[1, 2:, 1] = 1.0
    rod_targets = source_poses(DistillConfig(source_simulator="rod"), arm_s, programs)
    chain_targets = source_poses(DistillConfig(), arm_s, programs)
    np.testing.assert_allclose(rod_targets, mjx_arm.load_rod("source").rollout(programs))
    np.testing.assert_allclose(chain_targets, arm_s.rollout(programs, backend="c"))
    assert rod_targets.shape == chain_targets.shape == (2, 8, 6)
    # The two simulators differ, so the option changes what the teacher tracks.
    assert np.abs(rod_targets[:, :, :3] - chain_targets[:, :, :3]).max() > 1e-4


#: A committed translator (CCGAN-GP, k = 15) whose commands the correction runs.
CORRECTION_TRANSLATOR = "results/paper/rerun_2026-11-27/run/ccgan/translator_seed0.ckpt"


def test_a_correction_translator_gets_its_own_cache_key_and_a_missing_one_is_refused(small_xml):
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    corrected = DistillConfig(correction_translator=CORRECTION_TRANSLATOR)
    key = json.loads(teacher_cache_key(corrected, 15, arm_c))["correction"]
    assert key["domain"] == "constrained" and key["dtype"] == "float32"
    assert len(key["translator_sha256"]) == 64
    assert "correction" not in json.loads(teacher_cache_key(DistillConfig(), 15, arm_c))
    with pytest.raises(ConfigError, match="correction_translator"):
        DistillConfig(correction_translator="no/such/translator.ckpt")
    with pytest.raises(ConfigError, match="correction_dtype"):
        DistillConfig(correction_translator=CORRECTION_TRANSLATOR, correction_dtype="float16")


def test_the_corrected_targets_move_by_the_rods_difference_from_the_arm(small_xml):
    """x_s - (rod(u0) - arm(u0)) at every k-th period: the rod, the arm plus that difference,
    then traces x_s where the arm traces the corrected target."""
    from ccgan.distill.teacher import corrected_targets
    from ccgan.translator import load_translator

    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    programs = np.zeros((2, 6, 3))
    programs[:, 1:, 0] = 2.0
    programs[1, 3:, 2] = 1.5
    targets = arm_s.rollout(programs, backend="c")
    config = DistillConfig(correction_translator=CORRECTION_TRANSLATOR, correction_dtype="float64")
    k = 15
    got = corrected_targets(config, arm_c, programs, targets, k, log=lambda _: None)
    translator = load_translator(CORRECTION_TRANSLATOR)
    u0 = np.stack([translator.translate(p, x)[0] for p, x in zip(programs, targets, strict=True)])
    assert u0.shape == (2, 6 * k, 3)
    rod = mjx_arm.load_rod("constrained").rollout(u0)[:, k - 1 :: k]
    arm = arm_c.rollout(u0, backend="c")[:, k - 1 :: k]
    np.testing.assert_allclose(got, targets - (rod - arm), atol=1e-12)
    assert np.abs(got - targets)[..., :3].max() > 1e-5  # the rod is not the arm: it moves them
    with pytest.raises(ValueError, match="holds k = 15"):
        corrected_targets(config, arm_c, programs, targets, 20)


def test_the_corrected_targets_are_kept_beside_the_cache_and_read_back(small_xml, tmp_path):
    """The target's rollouts take minutes at full size: a run stopped while the teacher plans
    reads them back; another key, or other programs, computes them again."""
    from ccgan.distill.teacher import cached_corrected_targets, correction_path

    arm_s = mjx_arm.load(xml=small_xml, domain="source")
    arm_c = mjx_arm.load(xml=small_xml, domain="constrained")
    programs = np.zeros((1, 5, 3))
    programs[:, 1:, 1] = 2.5
    targets = arm_s.rollout(programs, backend="c")
    config = DistillConfig(correction_translator=CORRECTION_TRANSLATOR)
    cache = tmp_path / "teacher.npz"
    logs = []
    first = cached_corrected_targets(config, arm_c, programs, targets, 15, "A", cache, logs.append)
    assert correction_path(cache).is_file() and not any("read from" in m for m in logs)
    again = cached_corrected_targets(config, arm_c, programs, targets, 15, "A", cache, logs.append)
    np.testing.assert_array_equal(again, first)
    assert "read from" in logs[-1]
    # D_s poses that differ in their last bits (another machine's float64 rollouts) hit too
    noisy = cached_corrected_targets(
        config, arm_c, programs, targets + 1e-14, 15, "A", cache, logs.append
    )
    np.testing.assert_array_equal(noisy, first)
    assert "read from" in logs[-1]
    other = cached_corrected_targets(config, arm_c, programs, targets, 15, "B", cache, logs.append)
    np.testing.assert_allclose(other, first, atol=1e-12)  # computed again under key B
    assert "read from" not in logs[-1]
