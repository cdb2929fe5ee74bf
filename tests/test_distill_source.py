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
