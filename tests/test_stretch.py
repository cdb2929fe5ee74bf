"""The chain's stretch softening (`mjx_arm.stretch`): hinge torques are the rod's
(c(p) - k q) / e^3 with e read from the pressures, in MuJoCo C, with domains that scale the
springs."""

import dataclasses

import mujoco
import numpy as np
import pytest

import mjx_arm
from mjx_arm import constants, stretch
from mjx_arm.model_gen import ArmParams, generate_xml, softened_hinges

PARAMS = dataclasses.replace(ArmParams(), n_segments=4)


@pytest.fixture(scope="module")
def arm():
    return mjx_arm.load(xml=generate_xml(PARAMS))


def hinge_torques(arm, qpos, pressure):
    """Actuator and spring torques on every dof at `qpos` under `pressure` (bar)."""
    m = arm.mj_model
    data = mujoco.MjData(m)
    data.qpos[:] = qpos
    data.ctrl[:] = arm.chamber_controls.numpy(pressure)
    mujoco.mj_forward(m, data)
    return data.qfrc_actuator + data.qfrc_passive


def test_every_softened_hinge_bends_by_c_minus_kq_over_e_cubed(arm):
    m = arm.mj_model
    cc = arm.chamber_controls
    hinges = softened_hinges(PARAMS)
    assert len(cc.soften_ids) == len(hinges) > 0
    rng = np.random.default_rng(0)
    qpos = arm.rest_qpos + rng.normal(0.0, 0.05, m.nq)
    pressure = np.array([3.0, 1.0, 2.0])
    # Reference: the same model with the softening actuators' controls left at zero, the chain
    # of constant springs, at the same state.
    data = mujoco.MjData(m)
    data.qpos[:] = qpos
    data.ctrl[list(cc.chamber_ids)] = pressure
    mujoco.mj_forward(m, data)
    constant = data.qfrc_actuator + data.qfrc_passive
    softened = hinge_torques(arm, qpos, pressure)
    for joint, stiffness, weight in hinges:
        dof = m.jnt_dofadr[m.joint(joint).id]
        e = 1.0 + weight * PARAMS.stretch_per_bar * pressure.sum()
        assert e > 1.1  # 6 bar in all: the span is > 10% longer
        # rel 1e-5: the MJCF keeps 6 significant digits of stretch_per_bar.
        assert softened[dof] == pytest.approx(constant[dof] / e**3, rel=1e-5)
        # The constant chain's torque is the chamber couple minus the spring.
        chamber = constant[dof] + stiffness * qpos[m.jnt_qposadr[m.joint(joint).id]]
        assert abs(chamber) > 0.0
    # Slides and twists are not softened.
    others = [
        m.jnt_dofadr[j] for j in range(m.njnt) if m.joint(j).name not in {h[0] for h in hinges}
    ]
    np.testing.assert_allclose(softened[others], constant[others], rtol=1e-12, atol=1e-12)


def test_the_aged_domain_softens_with_its_springs():
    source = mjx_arm.load(xml=generate_xml(PARAMS))
    aged = mjx_arm.load(xml=generate_xml(PARAMS), domain="aged")
    s, a = source.chamber_controls, aged.chamber_controls
    assert a.stretch_per_bar == pytest.approx(s.stretch_per_bar / 0.7)
    ids = list(s.soften_ids)
    np.testing.assert_allclose(
        aged.mj_model.actuator_gainprm[ids, 1], 0.7 * source.mj_model.actuator_gainprm[ids, 1]
    )


def test_a_model_without_softening_gets_pressures_only():
    arm = mjx_arm.load(constants.LINEAR_LAW_MODEL_PATH)
    cc = arm.chamber_controls
    assert not cc.softens and cc.nu == 3
    np.testing.assert_array_equal(cc.numpy(np.array([[1.0, 2.0, 3.0]])), [[1.0, 2.0, 3.0]])


def test_softening_actuators_need_their_pair_and_numeric():
    xml = generate_xml(PARAMS)
    first = xml.index('<motor name="unload_')
    broken = xml[:first] + xml[xml.index("\n", first) + 1 :]
    with pytest.raises(ValueError, match="unloading pair"):
        stretch.from_model(mujoco.MjModel.from_xml_string(broken))
    no_numeric = xml.replace(f'name="{constants.CUSTOM_STRETCH_PER_BAR}"', 'name="other"')
    with pytest.raises(ValueError, match="stretch_per_bar"):
        stretch.from_model(mujoco.MjModel.from_xml_string(no_numeric))
