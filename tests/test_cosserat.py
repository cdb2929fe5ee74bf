"""The reference Cosserat rod against closed-form beam solutions, plus API smoke tests.

Static solves settle under heavy damping; each rod shape compiles once (the solvers are cached per
`CosseratParams`), so the whole file runs in well under a minute on two CPU cores.
"""

import dataclasses
import math

import numpy as np
import pytest

from mjx_arm import cosserat, rod_dynamics, rod_params, section
from mjx_arm.constants import P_MIN_BAR
from mjx_arm.cosserat import CosseratParams

NO_GRAVITY = CosseratParams(gravity_mps2=0.0)
#: Small tip load (N): 0.7% of the length in bending (F L^3 / 3 EI), so the linear theory holds.
TIP_LOAD_N = 0.007 * 3.0 * NO_GRAVITY.bend_stiffness_nm2 / NO_GRAVITY.length_m**2


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
    # The arm is stubby (L / g = 13 for the radius of gyration g = 15 mm), so shear adds
    # F L / (a G A) = 3.8% to F L^3 / 3EI with PyElastica's a = 4/3; the oracle is Timoshenko's
    # sum. 20 elements: the paper's count.
    assert cantilever_errors[20] < 0.02


def test_slender_cantilever_matches_euler_bernoulli_within_2_percent():
    # A solid disc of r = 1 cm: shear adds only 0.4%, so plain F L^3 / 3EI is the oracle. The
    # load scales with EI to keep the deflection small.
    disc = section.solid_disc(0.01)
    params = dataclasses.replace(
        NO_GRAVITY,
        area_m2=disc.area_m2,
        second_moment_m4=disc.second_moment_m4,
        polar_moment_m4=disc.polar_moment_m4,
    )
    force = TIP_LOAD_N * params.bend_stiffness_nm2 / NO_GRAVITY.bend_stiffness_nm2
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


@pytest.mark.parametrize("turn_rad", [math.pi / 2, math.pi])
def test_large_end_moment_bends_the_rod_into_the_exact_arc(turn_rad):
    # A couple M at the free end bends an inextensible, unshearable rod into a circle of
    # curvature M / EI at any angle; the rod has neither axial nor shear strain under a pure
    # couple, so the arc is exact for it too (e = 1 everywhere, so the stretch factors of the
    # default law change nothing at equilibrium). Nodes lie on the circle up to the
    # discretisation. Under that law a half-turn settles in ~46,000 steps, not ~3,600: its
    # couple falls as 1 / e^3 without the matching axial force, so the bent rod's stretch
    # mode couples to bending and decays slowly; 20 s of settling leaves room.
    params = dataclasses.replace(NO_GRAVITY, n_elements=20, settle_max_s=20.0)
    ei, length = params.bend_stiffness_nm2, params.length_m
    kappa = turn_rad / length
    state = settle(np.zeros(3), params, tip_couple_nm=(0.0, ei * kappa, 0.0))
    arc_s = np.linspace(0.0, length, params.n_elements + 1)
    arc = np.stack(
        [
            -(1.0 - np.cos(kappa * arc_s)) / kappa,
            np.zeros_like(arc_s),
            -np.sin(kappa * arc_s) / kappa,
        ],
        axis=-1,
    )
    np.testing.assert_allclose(state.x, arc, atol=1e-3 * length)
    # d3 of the last element is the arc's tangent at the element's middle, L - l / 2.
    d3_angle = math.acos(np.clip(state.q[-1, 2] @ np.array([0.0, 0.0, -1.0]), -1.0, 1.0))
    assert d3_angle == pytest.approx(kappa * (length - 0.5 * params.element_length_m), abs=1e-3)


def reissner_cantilever_tip(params: CosseratParams, force_n: float, n_steps: int = 4000):
    """Tip (lateral, axial) displacement (m) and angle (rad) of a clamped rod under a tip force
    perpendicular to its straight axis, by shooting on Reissner's planar rod equations with the
    rod's own laws. Per rest arc length s, with t = (cos theta, sin theta) along the axis, n its
    normal, P = (0, F), N = P.t and Q = P.n:

        x' = (1 + sigma3) t + sigma1 n,   M' = -(x' x P),   theta' = M e^k / EI,
        theta(0) = 0, M(L) = 0.

    Linear law (k = 0): sigma3 = N / EA, sigma1 = Q / aGA. Gazzola's law (k = 3): the stresses
    are divided by the stretch e = |x'|, so sigma3 = N e / EA and sigma1 = Q e / aGA, which
    with e^2 = (1 + sigma3)^2 + sigma1^2 gives e = (a + sqrt(1 - b^2)) / (1 - a^2 - b^2),
    a = N / EA, b = Q / aGA. Exact at any deflection; RK4 in arc length, bisection on M(0).
    """
    ea, gas, ei = params.axial_stiffness_n, params.shear_stiffness_n, params.bend_stiffness_nm2
    gazzola = params.law == "gazzola"
    h = params.length_m / n_steps

    def rhs(y):
        _, _, theta, moment = y
        t = np.array([math.cos(theta), math.sin(theta)])
        n = np.array([-math.sin(theta), math.cos(theta)])
        a, b = force_n * t[1] / ea, force_n * n[1] / gas
        e = (a + math.sqrt(1.0 - b * b)) / (1.0 - a * a - b * b) if gazzola else 1.0
        dx = (1.0 + a * e) * t + (b * e) * n
        return np.array([dx[0], dx[1], moment * e**3 / ei, -force_n * dx[0]])

    def shoot(moment0):
        y = np.array([0.0, 0.0, 0.0, moment0])
        for _ in range(n_steps):
            k1 = rhs(y)
            k2 = rhs(y + 0.5 * h * k1)
            k3 = rhs(y + 0.5 * h * k2)
            k4 = rhs(y + h * k3)
            y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        return y

    lo, hi = 0.0, force_n * params.length_m  # M(0) lies between 0 and the unbent rod's F L
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if shoot(mid)[3] > 0.0 else (mid, hi)  # M(L) > 0: too much
    y = shoot(0.5 * (lo + hi))
    return y[1], y[0] - params.length_m, y[2]


@pytest.mark.parametrize("law", cosserat.LAWS)
def test_large_deflection_cantilever_matches_reissner_elastica(law):
    # F L^2 / EI = 3: the tip turns 56 degrees and rises 5 cm, far outside linear theory (which
    # gives a tip deflection of F L^3 / 3 EI = L, 1.6 times the true one). The laws differ by
    # 0.8% in the lateral tip here: the force stretches the rod by up to F / EA ~ 0.7%.
    params = dataclasses.replace(NO_GRAVITY, n_elements=20, law=law)
    force = 3.0 * params.bend_stiffness_nm2 / params.length_m**2
    lateral, axial, tip_angle = reissner_cantilever_tip(params, force)
    assert tip_angle > math.radians(55)
    state = settle(np.zeros(3), params, tip_force_n=(force, 0.0, 0.0))
    rod_axial = -state.x[-1, 2] - params.length_m
    assert state.x[-1, 0] == pytest.approx(lateral, rel=0.005)
    assert abs(rod_axial - axial) < 0.002 * params.length_m
    rod_angle = math.acos(np.clip(state.q[-1, 2] @ np.array([0.0, 0.0, -1.0]), -1.0, 1.0))
    assert rod_angle == pytest.approx(tip_angle, abs=0.005)


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


def test_the_split_modules_are_what_cosserat_exports():
    # mjx_arm.cosserat keeps every name its callers import, as the same objects.
    for name in ("CosseratParams", "RodState", "LAWS", "DOMAIN_DAMPING_PER_S", "straight_state"):
        assert getattr(cosserat, name) is getattr(rod_params, name)
    assert cosserat.tip_pose is rod_dynamics.tip_pose
    assert set(cosserat.__all__) >= {"rollout", "rollout_fn", "static_pose", "static_state"}


def test_rod_constants_cast_arrays_and_keep_scalars():
    rod = rod_params.make_rod(CosseratParams(n_elements=5))
    single = rod.astype(np.float32)
    assert single.node_mass.dtype == single.rot_damp.dtype == np.float32
    np.testing.assert_allclose(single.inertia, rod.inertia, rtol=1e-6)
    assert single.dt == rod.dt and isinstance(single.trans_damp, float)
    assert single.stretch_factors is rod.stretch_factors is True


def test_held_pressure_rollout_reaches_the_static_pose():
    params = dataclasses.replace(CosseratParams(), n_elements=5)
    command = np.array([2.0, P_MIN_BAR, P_MIN_BAR])
    poses = cosserat.rollout(np.tile(command, (300, 1)), params)  # 30 s, valve included
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


@pytest.mark.parametrize("law", cosserat.LAWS)
def test_a_stretched_rod_bends_by_m_e_cubed_over_ei(law):
    # Equal pressures on chambers that span the whole rod stretch it uniformly to e = 1 + F / EA
    # (the active load is a rest strain, so no stress remains); an end couple M then bends it
    # into an arc whose curvature per rest length is M e^3 / EI under Gazzola's law (the
    # stretched section is thinner and softer) and M / EI under the linear law. The arc is
    # e L long with radius e / kappa, so it is exact for the discrete rod too.
    params = dataclasses.replace(
        NO_GRAVITY, n_elements=20, law=law, chamber_length_m=NO_GRAVITY.length_m
    )
    pressure = 3.0
    stretch = 1.0 + 3 * pressure * 1e5 * params.chamber_area_m2 / params.axial_stiffness_n
    assert stretch > 1.2  # 3 bar on every chamber: a 27% longer rod, 1.9x softer in bending
    moment = 0.5 * params.bend_stiffness_nm2 / params.length_m
    state = settle(np.full(3, pressure), params, tip_couple_nm=(0.0, moment, 0.0))
    kappa = moment / params.bend_stiffness_nm2 * (stretch**3 if law == "gazzola" else 1.0)
    arc_s = np.linspace(0.0, params.length_m, params.n_elements + 1)
    radius = stretch / kappa
    arc = radius * np.stack(
        [-(1.0 - np.cos(kappa * arc_s)), np.zeros_like(arc_s), -np.sin(kappa * arc_s)], axis=-1
    )
    np.testing.assert_allclose(state.x, arc, atol=1e-3 * params.length_m)
    d3_angle = math.acos(np.clip(state.q[-1, 2] @ np.array([0.0, 0.0, -1.0]), -1.0, 1.0))
    assert d3_angle == pytest.approx(
        kappa * (params.length_m - 0.5 * params.element_length_m), abs=1e-3
    )


def test_the_laws_agree_on_an_unstretched_rod():
    # The stretch factors are 1 at e = 1: under a small tip couple (no axial force, no
    # pressure) and in a short rollout under gravity alone, both laws give the same rod.
    base = dataclasses.replace(CosseratParams(), n_elements=10)
    small = 1e-3 * base.bend_stiffness_nm2 / base.length_m
    poses = {}
    for law in cosserat.LAWS:
        params = dataclasses.replace(base, law=law, gravity_mps2=0.0)
        poses[law] = settle(np.zeros(3), params, tip_couple_nm=(small, 0.0, 0.0)).x
    np.testing.assert_allclose(poses["gazzola"], poses["linear"], atol=1e-9)
    commands = np.full((5, 3), P_MIN_BAR)
    rolled = {
        law: cosserat.rollout(commands, dataclasses.replace(base, law=law)) for law in cosserat.LAWS
    }
    # Gravity stretches the rod by ~0.3%: the laws part at that order, no more.
    np.testing.assert_allclose(rolled["gazzola"], rolled["linear"], atol=5e-5)
    with pytest.raises(ValueError, match="unknown law"):
        CosseratParams(law="hooke").validate()
