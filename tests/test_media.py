"""Tests of mjx_arm.media: a medium (r, s) as the chain's Domain, and its 63% step time."""

import json

import pytest

import mjx_arm
from mjx_arm import constants, media
from mjx_arm.identify_family import resolved_viscosity_scale

K_BY_MEDIUM_JSON = constants.ROOT / "studies/results/cpu/k_by_medium/k_by_medium.json"


@pytest.fixture(scope="module")
def constrained_scale(constrained_arm):
    return resolved_viscosity_scale(constrained_arm)


def test_the_papers_drag_ratio_is_the_chains_constrained_medium(constrained_arm, constrained_scale):
    d_c = media.medium_domain(10, 1.0, constrained_scale)
    arm = mjx_arm.load(domain=d_c)
    assert d_c.name == "r10_s1"
    assert arm.mj_model.opt.viscosity == pytest.approx(constrained_arm.mj_model.opt.viscosity)
    # The map and its inverse; r = 1 is not the source medium (a linear note, not a fit).
    scale = media.viscosity_scale_of(3.7, constrained_scale)
    assert media.drag_ratio_of(scale, constrained_scale) == pytest.approx(3.7)
    assert media.viscosity_scale_of(1.0, constrained_scale) == pytest.approx(2.01, abs=0.01)


def test_step_time_is_the_one_studies_k_by_medium_measured(constrained_scale):
    """The committed study's 63% times (MuJoCo C) at the fast end and a soft medium."""
    rows = {(r["r"], r["s"]): r["t63_s"] for r in json.loads(K_BY_MEDIUM_JSON.read_text())["rows"]}
    for r, s in ((2.0, 1.0), (5.0, 0.6)):
        arm = mjx_arm.load(domain=media.medium_domain(r, s, constrained_scale))
        t63 = media.step_t63_s(arm, media.step_hold_s(r, s))
        assert t63 == pytest.approx(rows[(r, s)], abs=0.05)  # the 0.1 s sampling
