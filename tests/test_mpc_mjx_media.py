"""Tests of tracking.mpc_mjx's media (issue 51): programs planned in different media in one
jitted program plan as each does alone in its own arm, on a 2-segment arm."""

import numpy as np
import pytest

import mjx_arm
from mjx_arm.identify_family import DomainFamily
from mjx_arm.programs import circle, kite
from tracking import held, metrics, mpc, mpc_mjx


@pytest.fixture(scope="module")
def arms():
    """(xml, D_s, D_c) of a 2-segment solid-disc arm (tests/test_mpc_mjx.py's has 3; 2 keeps
    the three compiles of the tracker under a minute on 2 cores)."""
    xml = mjx_arm.generate_xml(mjx_arm.ArmParams(section="solid", n_segments=2))
    return xml, mjx_arm.load(xml=xml, domain="source"), mjx_arm.load(xml=xml, domain="constrained")


@pytest.mark.slow  # 71 s on one core: three MJX tracker compiles (docs/testing.md)
def test_programs_in_two_media_plan_as_each_alone_in_its_arm(arms):
    xml, arm_s, arm_c = arms
    family = DomainFamily.of(arm_c, fit=("viscosity_scale", "stiffness_scale"))
    base = family.base_theta()
    # A softer arm in a third of D_c's drag, and D_c itself.
    theta = np.stack([base + np.log([1 / 3, 0.7]), base])
    arm_soft = mjx_arm.load(xml=xml, domain=family.domain(theta[0]))
    assert arm_soft.mjx_model.opt.viscosity != arm_c.mjx_model.opt.viscosity
    k, cfg = 3, mpc.MpcConfig(horizon_steps=1, iterations=1)
    programs = np.stack([circle(0.7), kite(0.7)])
    targets = arm_s.rollout(programs, backend="c")
    both, info = mpc_mjx.track(
        arm_c, targets, k, programs, cfg, chunk_steps=4, media=(family, theta)
    )
    assert both.shape == (2, 7 * k, 3) and info["healthy"].all()
    alone = [
        mpc_mjx.track(arm, targets[s], k, programs[s], cfg, chunk_steps=4)[0]
        for s, arm in enumerate((arm_soft, arm_c))
    ]
    for s, arm in enumerate((arm_soft, arm_c)):
        # The family rebuilds the medium's fields in float32 from log-parameters, `load` in
        # float64 then rounds. At the first step the plans agree to that rounding (5e-4 bar
        # measured); later the flat cost along one chamber lets it move the commands by tenths
        # of a bar at equal cost (tests/test_mpc_mjx.py), so the tracking is compared there, to
        # that test's bound of float32 MJX against float64 C (0.02% measured here).
        np.testing.assert_allclose(both[s, :k], alone[s][:k], atol=2e-3)
        err_both, err_alone = (
            metrics.position_error_cm(held.run_dc(arm, c, k, "c"), targets[s]).mean()
            for c in (both[s], alone[s])
        )
        assert abs(err_both - err_alone) < 0.005 * err_alone
    # The media matter: D_c's first plan for the soft arm's program is 1.9 bar away.
    soft_in_c, _ = mpc_mjx.track(arm_c, targets[0], k, programs[0], cfg, chunk_steps=4)
    assert np.abs(both[0, :k] - soft_in_c[:k]).max() > 0.2


def test_media_must_be_a_family_of_the_arm_with_one_row_per_program(arms):
    xml, arm_s, arm_c = arms
    family = DomainFamily.of(arm_c, fit=("viscosity_scale",))
    targets, init = np.zeros((2, 5, 6)), np.zeros((2, 5, 3))
    with pytest.raises(ValueError, match="DomainFamily"):
        mpc_mjx.track(arm_c, targets, 2, init, media=family)
    with pytest.raises(ValueError, match=r"\[2, 1\]"):
        mpc_mjx.track(arm_c, targets, 2, init, media=(family, np.zeros((2, 2))))
    with pytest.raises(ValueError, match="finite"):
        mpc_mjx.track(arm_c, targets, 2, init, media=(family, np.full((2, 1), np.nan)))
    other = mjx_arm.generate_xml(mjx_arm.ArmParams(section="solid", n_segments=3))
    family_other = DomainFamily.of(mjx_arm.load(xml=other, domain="constrained"))
    with pytest.raises(ValueError, match="another arm"):
        mpc_mjx.track(arm_c, targets, 2, init, media=(family_other, np.zeros((2, 2))))


def test_a_resume_file_of_other_media_does_not_match(arms):
    _, _, arm_c = arms
    family = DomainFamily.of(arm_c)
    cfg = mpc.MpcConfig(horizon_steps=1)
    init, target = np.zeros((2, 4, 3)), np.zeros((2, 4, 6))
    theta = np.zeros((2, 2), np.float32)
    plain = mpc_mjx._fingerprint(arm_c, 2, cfg, init, target, 3)
    key = mpc_mjx._fingerprint(arm_c, 2, cfg, init, target, 3, (family, theta))
    assert key != plain
    assert key == mpc_mjx._fingerprint(arm_c, 2, cfg, init, target, 3, (family, theta.copy()))
    assert key != mpc_mjx._fingerprint(arm_c, 2, cfg, init, target, 3, (family, theta + 0.1))
