"""The generated MJCF: matches the generator, compiles, steps cleanly, and behaves."""

import dataclasses

import mujoco
import numpy as np
import pytest

import mjx_arm
from mjx_arm import ArmParams, constants, generate_xml
from mjx_arm.model_gen import softened_hinges


def test_committed_model_equals_generator_output():
    committed = constants.DEFAULT_MODEL_PATH.read_text()
    assert committed == generate_xml(ArmParams()), (
        "models/softarm.xml is stale: run `python -m mjx_arm.model_gen`"
    )


def test_the_solid_section_regenerates_the_frozen_solid_arm():
    # models/softarm_solid.xml is kept byte for byte for the data made with it; the generator's
    # solid section must still produce its physics.
    frozen = mujoco.MjModel.from_xml_path(str(constants.SOLID_MODEL_PATH))
    regenerated = mujoco.MjModel.from_xml_string(generate_xml(ArmParams(section="solid")))
    for field in ("jnt_stiffness", "dof_armature", "body_mass", "body_inertia", "wrap_prm"):
        np.testing.assert_allclose(getattr(regenerated, field), getattr(frozen, field), rtol=1e-6)
    np.testing.assert_allclose(regenerated.actuator_gainprm, frozen.actuator_gainprm, rtol=1e-6)
    assert regenerated.opt.viscosity == pytest.approx(frozen.opt.viscosity, rel=1e-6)


def test_the_isupport_section_is_15_times_softer_than_the_solid_disc():
    tubes, disc = ArmParams(), ArmParams(section="solid")
    # SoRoMoX's I-Support numbers: I = 3 pi/4 (r_o^4 - r_i^4) + 3/2 A_t d^2 = 4.22e-8 m^4.
    assert tubes.second_moment_m4 == pytest.approx(4.217e-8, rel=1e-3)
    assert disc.second_moment_m4 / tubes.second_moment_m4 == pytest.approx(15.09, rel=1e-3)
    assert tubes.area_m2 == pytest.approx(3 * np.pi * (0.00779**2 - 0.00639**2), rel=1e-9)
    assert tubes.polar_moment_m4 == pytest.approx(2 * tubes.second_moment_m4)
    assert tubes.mass_kg == disc.mass_kg == 0.183
    with pytest.raises(ValueError, match="unknown section"):
        ArmParams(section="hollow")


@pytest.mark.parametrize("n_segments", [3, 5, 10, 20])
def test_segment_counts_compile_with_chamber_ending_at_its_length(n_segments):
    params = dataclasses.replace(ArmParams(), n_segments=n_segments)
    m = mujoco.MjModel.from_xml_string(generate_xml(params))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    # Three chambers, and a softening and an unloading actuator per hinge the chamber spans.
    assert m.nu == 3 + 2 * len(softened_hinges(params)) and m.ntendon == 3
    weights = [w for _, _, w in softened_hinges(params)]
    assert all(0.0 < w <= 1.0 for w in weights) and weights[0] == 1.0
    # Each chamber's fixed tendon stretches by exactly the chamber's length per unit strain.
    seg = params.segment_length_m
    for k in range(3):
        adr, num = m.tendon_adr[k], m.tendon_num[k]
        stretch = [
            m.wrap_prm[w]
            for w in range(adr, adr + num)
            if m.joint(int(m.wrap_objid[w])).name.startswith("stretch_")
        ]
        assert sum(stretch) * seg == pytest.approx(params.chamber_length_m, rel=1e-5)
    np.testing.assert_allclose(d.ten_length, 0.0, atol=1e-12)  # fixed tendons: zero at qpos0
    np.testing.assert_allclose(m.body_mass[1:].sum(), params.mass_kg, rtol=1e-5)
    tip = m.site(constants.TIP_SITE).id
    np.testing.assert_allclose(d.site_xpos[tip], [0, 0, -params.length_m], atol=1e-6)
    np.testing.assert_allclose(d.site_xmat[tip].reshape(3, 3)[:, 2], [0, 0, -1], atol=1e-12)


def test_generator_rejects_bad_parameters():
    with pytest.raises(ValueError, match="medium_drag"):
        generate_xml(dataclasses.replace(ArmParams(), medium_drag_ns_per_m2=0.0))
    with pytest.raises(ValueError, match="n_segments"):
        generate_xml(dataclasses.replace(ArmParams(), n_segments=1))


@pytest.mark.parametrize("domain", ["source", "constrained"])
def test_ten_seconds_of_random_pressures_raise_no_mujoco_warning(domain):
    arm = mjx_arm.load(domain=domain)
    m = arm.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = arm.rest_qpos
    rng = np.random.default_rng(0)
    for _ in range(100):  # 100 control periods of 0.1 s
        d.ctrl[:] = arm.chamber_controls.numpy(rng.uniform(0.0, 3.5, 3))
        mujoco.mj_step(m, d, nstep=arm.n_substeps)
    assert all(w.number == 0 for w in d.warning), [
        (mujoco.mjtWarning(i).name, w.number) for i, w in enumerate(d.warning) if w.number
    ]
    assert np.isfinite(d.qpos).all()
    assert d.time == pytest.approx(10.0)


def test_chamber_force_bends_a_free_chain_into_the_rods_arc():
    """A chamber force F puts the couple F r on every spanned joint: without gravity the tip
    slope is F r L_c / (E I) (pure bending over the chamber span), the rod's closed form."""
    params = dataclasses.replace(
        ArmParams(), gravity_mps2=0.0, stiffness_scale=1.0, chamber_gain_scale=1.0
    )
    arm = mjx_arm.load(xml=generate_xml(params), domain=mjx_arm.Domain(inertia_scale=None))
    m = arm.mj_model
    d = mujoco.MjData(m)
    d.qpos[:] = arm.rest_qpos
    d.ctrl[:] = arm.chamber_controls.numpy(np.array([2.0, 0.0, 0.0]))  # softening included
    mujoco.mj_step(m, d, nstep=20000)
    force = 2.0 * params.chamber_gain_n_per_bar
    e_i = params.youngs_modulus_pa * params.second_moment_m4
    slope = force * params.chamber_offset_m * params.chamber_length_m / e_i
    d3 = d.site_xmat[m.site(constants.TIP_SITE).id].reshape(3, 3)[:, 2]
    rest_d3 = np.array([0.0, 0.0, -1.0])
    angle = np.arccos(np.clip(d3 @ rest_d3, -1, 1))
    assert angle == pytest.approx(slope, rel=0.02)
    # Chamber 0 sits at +x: lengthening it bends the arm toward -x.
    assert d.site_xpos[m.site(constants.TIP_SITE).id][0] < -0.005


@pytest.mark.parametrize("alternate", [True, False])
def test_alternating_hinge_order_keeps_a_chamber_in_its_bending_plane(alternate):
    # Chamber 1 (120 deg) bends the arm about a skewed axis; x-then-y hinges everywhere add a
    # twist of ab/2 per joint that turns the bending plane, alternating the order cancels it.
    params = dataclasses.replace(ArmParams(), alternate_bend=alternate)
    arm = mjx_arm.load(xml=generate_xml(params))
    tip = arm.rollout(np.tile([0.2, 3.5, 0.2], (150, 1)), backend="c")[-1]
    away = -np.array([np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3)])
    direction = tip[:2] / np.linalg.norm(tip[:2])
    off_plane = abs(away[0] * direction[1] - away[1] * direction[0])  # sine of the angle
    if alternate:
        assert off_plane < 0.005
    else:
        assert off_plane > 0.03
