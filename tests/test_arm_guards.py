"""Guards of the arm API: bad input is refused up front with a clear error, and a divergence is
never lost (3-segment arms, short rollouts)."""

import re

import numpy as np
import pytest

import mjx_arm
from mjx_arm import valve


@pytest.fixture(scope="module")
def small_arm(small_xml):
    return mjx_arm.load(xml=small_xml)


@pytest.fixture(scope="module")
def unstable_arm(small_xml):
    """An arm that loads (its rest comes from the stable model) but diverges once driven.

    Masses, inertias and armature x 1e-6 with gravity x 1e6 keep the statics (so the rest is
    still an equilibrium) while the explicit drag rate grows a million times, far past the
    Euler stability limit, whatever the arm's stiffness and medium.
    """
    arm = mjx_arm.load(xml=small_xml)
    m = arm.mj_model
    for field in (m.body_mass, m.body_inertia, m.dof_armature):
        field[:] *= 1e-6
    m.opt.gravity[:] /= 1e-6
    return arm


def _with_numeric(xml: str, name: str, value: float) -> str:
    """The MJCF with the <custom> numeric `name` set to `value`."""
    out, n = re.subn(rf'(<numeric name="{name}" data=")[^"]*(")', rf"\g<1>{value}\g<2>", xml)
    assert n == 1, f"the generated MJCF has no numeric {name}"
    return out


# ---------------------------------------------------------------------------------- batches


@pytest.mark.parametrize("backend", ["c", "mjx"])
def test_empty_batch_is_refused_before_any_work(small_arm, backend):
    with pytest.raises(ValueError, match=r"B, T > 0, got \(0, 5, 3\)"):
        small_arm.rollout(np.zeros((0, 5, 3)), backend=backend)
    with pytest.raises(ValueError, match=r"B, T > 0"):
        small_arm.rollout_c_from(small_arm.rest_state(1), np.zeros((0, 5, 3)))


@pytest.mark.parametrize("batch", [-1, 0, 1.5, "2"])
def test_rest_state_needs_a_positive_int(small_arm, batch):
    with pytest.raises(ValueError, match="batch must be an int >= 1"):
        small_arm.rest_state(batch)
    assert small_arm.rest_state(np.int64(2)).physics.shape[0] == 2


# ---------------------------------------------------------------------------------- divergence


@pytest.mark.parametrize("backend", ["c", "mjx"])
def test_diverging_simulation_is_reported_not_returned(unstable_arm, backend):
    with pytest.raises(mjx_arm.SimulationDivergedError, match="diverged") as info:
        unstable_arm.rollout(np.full((2, 10, 3), 3.5), backend=backend)
    assert info.value.trajectories.tolist() == [0, 1]


def test_divergence_survives_chained_c_rollouts(unstable_arm):
    """MuJoCo C resets a diverged state: continuing from it must not look healthy."""
    program = np.full((2, 5, 3), 0.2)
    program[:, :, 0] = 3.5
    poses, ok, end = unstable_arm.rollout_c_from(unstable_arm.rest_state(2), program)
    assert not ok[:, -1].any() and end.diverged.tolist() == [True, True]
    _, ok_next, end_next = unstable_arm.rollout_c_from(end, program)
    assert not ok_next.any() and end_next.diverged.all()


def test_diverged_flag_of_a_start_state_is_honoured(small_arm):
    program = np.full((3, 4, 3), 1.0)
    start = small_arm.rest_state(3)._replace(diverged=np.array([False, True, False]))
    start.physics[2, 1] = np.nan  # a non-finite start is diverged too
    _, ok, end = small_arm.rollout_c_from(start, program)
    assert ok[0].all() and not ok[1].any() and not ok[2].any()
    assert end.diverged.tolist() == [False, True, True]
    # A state built by hand without the flag (as before it existed) counts as healthy.
    by_hand = mjx_arm.SimState(start.physics[:1], start.pressure_bar[:1])
    assert small_arm.rollout_c_from(by_hand, program[:1])[1].all()


# ---------------------------------------------------------------------------------- load


def test_unstable_domain_is_refused_at_load(small_xml, small_arm):
    """An inertia scale far below the automatic one must not load with an absurd rest (the
    committed arm at inertia_scale=1.0 settled with its slide joint 80 km long)."""
    too_light = mjx_arm.Domain(name="light", inertia_scale=small_arm.inertia_scale * 1e-3)
    with pytest.raises(mjx_arm.SimulationDivergedError, match=r"Domain\.inertia_scale=") as err:
        mjx_arm.load(xml=small_xml, domain=too_light)
    assert "'light'" in str(err.value) and "no stable rest" in str(err.value)


def test_load_refuses_what_is_not_an_mjcf(tmp_path, small_xml):
    with pytest.raises(mjx_arm.ModelValidationError, match="MJCF string does not parse"):
        mjx_arm.load(xml="<mujoco><worldbody>")
    with pytest.raises(mjx_arm.ModelValidationError, match="is not a file"):
        mjx_arm.load(tmp_path)
    npz = tmp_path / "data.npz"
    np.savez(npz, x=np.arange(1000.0))
    with pytest.raises(mjx_arm.ModelValidationError, match="data.npz is not an MJCF text file"):
        mjx_arm.load(npz)
    broken = tmp_path / "broken.xml"
    broken.write_text(small_xml[: len(small_xml) // 2])
    with pytest.raises(mjx_arm.ModelValidationError, match="broken.xml does not parse"):
        mjx_arm.load(broken)
    model = tmp_path / "arm.xml"
    model.write_text(small_xml)
    with pytest.raises(ValueError, match="not both"):
        mjx_arm.load(model, xml=small_xml)


@pytest.mark.parametrize(
    "name, value, message",
    [
        ("valve_p_max", 10.0, r"valve_p_max = 10 bar is above the chamber actuators' ctrlrange"),
        ("valve_tau_rise", 0.0, r"valve_tau_rise = 0 s must be > 0"),
        ("valve_tau_drop", -0.1, r"valve_tau_drop = -0.1 s must be > 0"),
        ("valve_p_min", -1.0, r"valve_p_min = -1 bar must be >= 0"),
        ("valve_p_min", 3.5, r"valve_p_min = 3.5 bar must be below valve_p_max"),
    ],
)
def test_unusable_valve_numerics_are_refused(small_xml, name, value, message):
    with pytest.raises(mjx_arm.ModelValidationError, match=message):
        mjx_arm.load(xml=_with_numeric(small_xml, name, value))


def test_valve_check_lists_every_problem():
    bad = valve.ValveParams(tau_rise_s=float("nan"), tau_drop_s=0.0, p_min_bar=2.0, p_max_bar=1.0)
    with pytest.raises(ValueError) as err:
        valve.check(bad, ctrl_range=(0.0, 0.5))
    for part in ("tau_rise_s = nan is not finite", "tau_drop_s = 0 s", "below p_max_bar", "0.5"):
        assert part in str(err.value)
    assert valve.check(valve.ValveParams(), ctrl_range=(0.0, 3.5)) == valve.ValveParams()


@pytest.mark.parametrize("timestep", ["-0.004", "0"])
def test_a_timestep_that_is_not_positive_is_named_by_its_sign(small_xml, timestep):
    xml, n = re.subn(r'timestep="[^"]*"', f'timestep="{timestep}"', small_xml)
    assert n == 1
    with pytest.raises(mjx_arm.ModelValidationError, match="must be positive") as exc:
        mjx_arm.load(xml=xml)
    assert "lower the timestep" not in str(exc.value)


def test_an_mjcf_without_its_constrained_medium_needs_a_domain(small_xml):
    """Without <custom> constrained_viscosity_scale the constrained and aged domains have no
    scale: refused (never the solid-disc arm's); a Domain with a scale, or the source, loads."""
    bare, n = re.subn(r'\s*<numeric name="constrained_viscosity_scale"[^>]*/>', "", small_xml)
    assert n == 1
    for domain in ("constrained", "aged"):
        with pytest.raises(mjx_arm.ModelValidationError, match="pass a mjx_arm.Domain"):
            mjx_arm.load(xml=bare, domain=domain)
    source = mjx_arm.load(xml=bare)
    arm = mjx_arm.load(xml=bare, domain=mjx_arm.Domain(name="c", viscosity_scale=20.0))
    assert arm.mj_model.opt.viscosity == pytest.approx(20.0 * source.mj_model.opt.viscosity)
    # The committed solid-disc arm predates the numeric and keeps its fitted medium.
    solid = mjx_arm.load(mjx_arm.constants.SOLID_MODEL_PATH, domain="constrained")
    assert (
        solid.mj_model.opt.viscosity
        > mjx_arm.load(mjx_arm.constants.SOLID_MODEL_PATH).mj_model.opt.viscosity
    )


# ------------------------------------------------------------------ argument types, before work


@pytest.mark.parametrize("chunk", [2.5, "8", None, True, np.float64(4.0)])
@pytest.mark.parametrize("backend", ["c", "mjx"])
def test_a_chunk_that_is_not_an_int_is_refused_by_name(small_arm, chunk, backend, monkeypatch):
    monkeypatch.setattr(type(small_arm), "_rollout_mjx", lambda *a: pytest.fail("simulated"))
    monkeypatch.setattr(type(small_arm), "_rollout_c", lambda *a, **k: pytest.fail("simulated"))
    with pytest.raises(TypeError, match=r"chunk must be an int >= 1 \(trajectories per call\)"):
        small_arm.rollout(np.ones((2, 3)), backend=backend, chunk=chunk)
    with pytest.raises(TypeError, match="chunk must be an int"):
        small_arm.rollout_c_from(small_arm.rest_state(1), np.ones((1, 2, 3)), chunk=chunk)


def test_chunk_below_one_is_refused(small_arm):
    with pytest.raises(ValueError, match="chunk must be an int >= 1"):
        small_arm.rollout(np.ones((2, 3)), backend="c", chunk=0)


@pytest.mark.parametrize(
    "pressures", [np.ones((2, 3), bool), [[True, False, True]], [["1.0", "2", "3"]], [[1j, 0, 0]]]
)
def test_pressures_must_be_real_numbers_not_bools(small_arm, pressures):
    with pytest.raises(TypeError, match="pressures_bar must be real numbers in bar"):
        small_arm.rollout(pressures, backend="c")
    with pytest.raises(TypeError, match="pressures_bar must be real numbers in bar"):
        mjx_arm.check_pressures(pressures)


def test_integer_pressures_are_bar(small_arm):
    np.testing.assert_array_equal(
        small_arm.rollout(np.ones((2, 3), int), backend="c"),
        small_arm.rollout(np.ones((2, 3)), backend="c"),
    )


@pytest.mark.parametrize(
    "start", [(np.zeros((1, 5)), np.zeros((1, 3))), np.zeros((1, 5)), {"physics": 0}]
)
def test_a_start_that_is_not_a_sim_state_is_named(small_arm, start):
    with pytest.raises(TypeError, match=r"start must be a mjx_arm.SimState \(Arm.rest_state"):
        small_arm.rollout_c_from(start, np.ones((1, 2, 3)))


@pytest.mark.parametrize(
    "field, value, error",
    [
        ("viscosity", "5", TypeError),
        ("viscosity", True, TypeError),
        ("viscosity", np.float32(-1), ValueError),
        ("viscosity", 1 + 0j, TypeError),
        ("viscosity_scale", np.bool_(True), TypeError),
        ("stiffness_scale", None, TypeError),
        ("stiffness_scale", -0.7, ValueError),
        ("mass_scale", float("nan"), ValueError),
        ("inertia_scale", 0, ValueError),
        ("name", 3, TypeError),
    ],
)
def test_domain_refuses_non_real_bool_and_negative_fields(field, value, error):
    with pytest.raises(error, match=f"Domain.{field} must be"):
        mjx_arm.Domain(**{field: value})


def test_domain_keeps_valid_numpy_scalars_as_floats():
    domain = mjx_arm.Domain(viscosity=np.float32(5.0), stiffness_scale=np.int64(1), mass_scale=2)
    assert domain.viscosity == 5.0 and type(domain.viscosity) is float
    assert type(domain.stiffness_scale) is float and domain.mass_scale == 2.0
    assert mjx_arm.Domain(viscosity_scale=None).viscosity_scale is None


@pytest.mark.parametrize("n_segments", [10.5, "10", True])
def test_n_segments_must_be_a_whole_number(n_segments):
    import dataclasses

    params = dataclasses.replace(mjx_arm.ArmParams(), n_segments=n_segments)
    with pytest.raises(TypeError, match="n_segments must be an int >= 2"):
        mjx_arm.generate_xml(params)


def test_the_first_mjx_compile_of_a_batch_shape_is_announced_once(small_arm, capsys, monkeypatch):
    """A cold MJX compile takes a minute or more and printed nothing: one stderr line before the
    first call of each batch shape, none after (the jitted call itself is replaced: no compile)."""
    calls = []
    monkeypatch.setitem(
        small_arm.__dict__,
        "_jit_batched",
        lambda model, commands: (
            calls.append(commands.shape)
            or (np.zeros(commands.shape[:2] + (6,)), np.ones(commands.shape[:2], bool))
        ),
    )
    small_arm.rollout(np.ones((4, 7, 3)))
    small_arm.rollout(np.ones((4, 7, 3)))
    err = capsys.readouterr().err
    assert err.count("compiling the MJX rollout for batch 4 x 7 steps (about ") == 1, err
    assert "the first time on this machine" in err
    small_arm.rollout(np.ones((5, 7, 3)))
    assert "batch 5 x 7 steps" in capsys.readouterr().err
    assert calls == [(4, 7, 3), (4, 7, 3), (5, 7, 3)]
