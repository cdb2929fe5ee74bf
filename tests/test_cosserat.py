"""The reference Cosserat rod against closed-form beam solutions, plus API smoke tests.

Static solves settle under heavy damping; each rod shape compiles once (the solvers are cached per
`CosseratParams`), so the whole file runs in well under a minute on two CPU cores.
"""

import dataclasses
import math

import numpy as np
import pytest

from mjx_arm import cosserat
from mjx_arm.constants import P_MIN_BAR
from mjx_arm.cosserat import CosseratParams

NO_GRAVITY = CosseratParams(gravity_mps2=0.0)
#: Small tip load (N): about 1.3 mm of deflection, 0.7% of the length, so the linear theory holds.
TIP_LOAD_N = 0.5


def settle(pressures_bar, params, **loads) -> cosserat.RodState:
    state, steps = cosserat.static_state(pressures_bar, params, **loads)
    max_steps = params.settle_max_s / params.timestep_s
    assert steps < 0.9 * max_steps, "static solve did not converge"
    return state


def timoshenko_tip_deflection(params: CosseratParams, force_n: float) -> float:
    """Cantilever tip deflection (m): bending F L^3 / 3EI plus shear F L / (a G A)."""
    bending = force_n * params.length_m**3 / (3.0 * params.bend_stiffness_nm2)
    return bending + force_n * params.length_m / params.shear_stiffness_n


@pytest.fixture(scope="module")
def cantilever_errors():
    """Relative tip-deflection error against Timoshenko, for 5, 10 and 20 elements."""
    errors = {}
    for n in (5, 10, 20):
        params = dataclasses.replace(NO_GRAVITY, n_elements=n)
        state = settle(np.zeros(3), params, tip_force_n=(TIP_LOAD_N, 0.0, 0.0))
        expected = timoshenko_tip_deflection(params, TIP_LOAD_N)
        errors[n] = abs(state.x[-1, 0] / expected - 1.0)
        # The load is in the xz plane; nothing may leave it.
        assert abs(state.x[-1, 1]) < 1e-9
    return errors


def test_cantilever_tip_load_matches_beam_theory_within_2_percent(cantilever_errors):
    # The arm is stubby (L / r = 6.7), so shear adds F L / (a G A) = 3.8% to F L^3 / 3EI with
    # PyElastica's a = 4/3; the oracle is Timoshenko's sum. 20 elements: the paper's count.
    assert cantilever_errors[20] < 0.02


def test_slender_cantilever_matches_euler_bernoulli_within_2_percent():
    # At r = 1 cm shear adds only 0.4%, so plain F L^3 / 3EI is the oracle. The load scales with
    # EI to keep the deflection small (r^4: 81 times softer).
    params = dataclasses.replace(NO_GRAVITY, radius_m=0.01)
    force = TIP_LOAD_N / 81.0
    state = settle(np.zeros(3), params, tip_force_n=(0.0, force, 0.0))
    expected = force * params.length_m**3 / (3.0 * params.bend_stiffness_nm2)
    assert state.x[-1, 1] == pytest.approx(expected, rel=0.02)


def test_cantilever_error_falls_as_elements_are_added(cantilever_errors):
    e5, e10, e20 = cantilever_errors[5], cantilever_errors[10], cantilever_errors[20]
    assert e5 > e10 > e20
    # The clamp is a half-length Voronoi domain, so the scheme is second order: doubling the
    # elements divides the error by about four (measured 1.9%, 0.48%, 0.12%).
    assert e5 / e10 > 3.0 and e10 / e20 > 3.0


def test_pure_end_moment_bends_the_rod_into_a_circular_arc():
    params = NO_GRAVITY
    ei, length = params.bend_stiffness_nm2, params.length_m
    moment = ei / length  # kappa L = 1 rad: far from small deflections
    radius = ei / moment  # kappa = M / EI
    state = settle(np.zeros(3), params, tip_couple_nm=(0.0, moment, 0.0))
    # A couple about +y turns d3 = -z toward -x: the arc's centre is at (-R, 0, 0).
    centre = np.array([-radius, 0.0, 0.0])
    node_radii = np.linalg.norm(state.x - centre, axis=-1)
    np.testing.assert_allclose(node_radii, radius, rtol=0.02)
    np.testing.assert_allclose(state.x[:, 1], 0.0, atol=1e-9)
    kappa = 1.0 / radius
    arc_tip = np.array(
        [-(1.0 - math.cos(kappa * length)) / kappa, 0.0, -math.sin(kappa * length) / kappa]
    )
    assert np.linalg.norm(state.x[-1] - arc_tip) < 0.02 * length


@pytest.mark.parametrize("n_elements", [5, 20])
def test_equal_pressures_stretch_the_chamber_span_by_f_l_over_ea(n_elements):
    # With 5 elements the chamber ends mid-element (0.18 m = 4.5 elements of 0.04 m).
    params = dataclasses.replace(NO_GRAVITY, n_elements=n_elements)
    pressure = 1.0
    state = settle(np.full(3, pressure), params)
    force = 3 * pressure * 1e5 * params.chamber_area_m2
    expected = force * params.chamber_length_m / params.axial_stiffness_n
    stretch = -state.x[-1, 2] - params.length_m
    assert stretch == pytest.approx(expected, rel=0.02)
    # The three bending couples cancel.
    np.testing.assert_allclose(state.x[-1, :2], 0.0, atol=1e-9)
    np.testing.assert_allclose(state.q[-1, 2], [0.0, 0.0, -1.0], atol=1e-9)


@pytest.mark.parametrize("chamber", [0, 1, 2])
def test_a_chamber_bends_the_tip_away_from_itself(chamber):
    params = dataclasses.replace(CosseratParams(), n_elements=10)
    rest = cosserat.static_pose(np.full(3, P_MIN_BAR), params)
    pressures = np.full(3, P_MIN_BAR)
    pressures[chamber] = 1.5
    pose = cosserat.static_pose(pressures, params)
    shift = pose[:2] - rest[:2]
    angle = 2.0 * math.pi * chamber / 3.0
    away = -np.array([math.cos(angle), math.sin(angle)])
    assert np.linalg.norm(shift) > 2e-3  # about 6 mm at 1.3 bar above the floor
    assert shift @ away / np.linalg.norm(shift) > math.cos(math.radians(0.5))
    np.testing.assert_allclose(np.linalg.norm(pose[3:]), 1.0, atol=1e-9)


def test_batched_rollout_has_the_right_shape_and_no_nan():
    params = dataclasses.replace(CosseratParams(), n_elements=5)
    rng = np.random.default_rng(0)
    commands = rng.uniform(-1.0, 5.0, size=(3, 4, 3))  # out of range: the valve saturates
    poses = cosserat.rollout(commands, params)
    assert poses.shape == (3, 4, 6) and poses.dtype == np.float64
    assert np.isfinite(poses).all()
    np.testing.assert_allclose(np.linalg.norm(poses[..., 3:], axis=-1), 1.0, atol=1e-9)
    single = cosserat.rollout(commands[1], params)
    assert single.shape == (4, 6)
    np.testing.assert_allclose(single, poses[1], atol=1e-12)


def test_held_pressure_rollout_reaches_the_static_pose():
    params = dataclasses.replace(CosseratParams(), n_elements=5)
    command = np.array([2.0, P_MIN_BAR, P_MIN_BAR])
    poses = cosserat.rollout(np.tile(command, (60, 1)), params)  # 6 s, valve included
    np.testing.assert_allclose(poses[-1], cosserat.static_pose(command, params), atol=1e-5)
    rest = cosserat.static_pose(np.full(3, P_MIN_BAR), params)
    np.testing.assert_allclose(cosserat.rest_state(params).x[-1], rest[:3], atol=1e-12)


def test_parameters_are_checked():
    with pytest.raises(ValueError, match="stability"):
        CosseratParams(dt_s=1e-3).validate()
    with pytest.raises(ValueError, match="divide"):
        CosseratParams(dt_s=3e-5 * 1.01).validate()
    with pytest.raises(ValueError, match="unknown domain"):
        CosseratParams.for_domain("vacuum")
    assert CosseratParams.for_domain("constrained").damping_per_s == 8000.0
    # The default timestep sits below the estimated limit, which the measured limit confirms:
    # 0.9x of it ran 20000 undamped steps, 1.0x diverged (n = 5 and 20).
    params = CosseratParams()
    assert params.timestep_s <= params.cfl * params.critical_dt_s
