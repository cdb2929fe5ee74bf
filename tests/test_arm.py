"""The arm API: loading, validation, rollouts on both backends, bad input, and the physics."""

import dataclasses
import os
import time

import numpy as np
import pytest

import mjx_arm
from mjx_arm import ArmParams, generate_xml
from mjx_arm.arm import time_constant_63

# MJX (float32) and MuJoCo C (float64) integrate the same Euler steps; they agree far better than
# this, which is 1% of the smallest tip motion the tests look at.
POSITION_TOL_M = 5e-5
D3_TOL = 5e-4


def _held(pressure_bar, seconds):
    return np.tile(np.asarray(pressure_bar, dtype=float), (int(round(seconds * 10)), 1))


def test_xla_cpu_flag_is_set_by_the_package():
    if mjx_arm.CPU_FUSION_FLAG_NEEDED:
        assert mjx_arm.CPU_FUSION_FLAG in os.environ["XLA_FLAGS"]
    else:
        assert mjx_arm.CPU_FUSION_FLAG not in os.environ.get("XLA_FLAGS", "")


def test_rollout_shapes_and_rest_start(source_arm):
    program = _held([0.2, 0.2, 0.2], 0.5)
    poses = source_arm.rollout(program, backend="c")
    assert poses.shape == (5, 6)
    # Held at the valve floor, the arm stays at rest.
    np.testing.assert_allclose(poses, np.tile(source_arm.rest_pose(), (5, 1)), atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(poses[:, 3:], axis=-1), 1.0, atol=1e-9)
    batched = source_arm.rollout(np.stack([program, program]), backend="c")
    assert batched.shape == (2, 5, 6)


@pytest.mark.parametrize("domain", ["source", "constrained"])
def test_mjx_and_mujoco_c_agree_on_tip_poses(domain):
    arm = mjx_arm.load(domain=domain)
    rng = np.random.default_rng(1)
    programs = np.repeat(rng.uniform(0.0, 3.5, (2, 3, 3)), 10, axis=1)  # 3 targets held 1 s
    poses_c = arm.rollout(programs, backend="c")
    poses_mjx = arm.rollout(programs, backend="mjx")
    position_error = np.linalg.norm(poses_c[..., :3] - poses_mjx[..., :3], axis=-1)
    assert position_error.max() < POSITION_TOL_M
    assert np.abs(poses_c[..., 3:] - poses_mjx[..., 3:]).max() < D3_TOL
    # The programs must actually move the tip for the agreement to mean anything.
    assert np.ptp(poses_c[..., :2]) > 2e-3


def test_each_chamber_bends_away_and_all_three_lengthen(source_arm):
    rest = source_arm.rest_pose()
    directions = []
    for chamber in range(3):
        command = [0.2, 0.2, 0.2]
        command[chamber] = 3.5
        tip = source_arm.rollout(_held(command, 3.0), backend="c")[-1, :3]
        lateral = tip[:2] - rest[:2]
        angle = 2 * np.pi * chamber / 3
        chamber_dir = np.array([np.cos(angle), np.sin(angle)])
        assert np.linalg.norm(lateral) > 5e-3  # more than 5 mm sideways
        cosine = lateral @ chamber_dir / np.linalg.norm(lateral)
        assert cosine < -0.99, f"chamber {chamber} bends toward {lateral}, not away"
        directions.append(lateral)
    all_three = source_arm.rollout(_held([3.5, 3.5, 3.5], 3.0), backend="c")[-1, :3]
    assert all_three[2] < rest[2] - 1e-3  # tip more than 1 mm lower: the arm lengthened
    assert np.linalg.norm(all_three[:2] - rest[:2]) < 1e-4  # and stayed straight


def test_constrained_domain_same_statics_but_slower(source_arm, constrained_arm):
    # The constrained medium's 63% time is about 35 s at 2 bar, longer at 3.5 bar, where the
    # stretched arm is softer (1 / e^3 = 0.64): hold long enough for it to settle.
    program = np.concatenate([_held([0.2, 0.2, 0.2], 0.1), _held([3.5, 0.2, 0.2], 699.9)])
    times = np.arange(1, len(program) + 1) * 0.1
    t63 = {}
    finals = {}
    for name, arm in [("source", source_arm), ("constrained", constrained_arm)]:
        poses = arm.rollout(program, backend="c")
        deflection = np.linalg.norm(poses[:, :3] - arm.rest_pose()[:3], axis=-1)
        t63[name] = time_constant_63(times, deflection)
        finals[name] = poses[-1]
    print(
        f"\n63% step-response time: source {t63['source']:.2f} s, "
        f"constrained {t63['constrained']:.2f} s"
    )
    np.testing.assert_allclose(finals["source"][:3], finals["constrained"][:3], atol=2e-4)
    assert t63["constrained"] > 3.0 * t63["source"]


def test_custom_domain_softer_arm_bends_more(source_arm):
    # Without gravity the bend angle is the chamber couple over the stiffness, so a 0.7x arm
    # bends 1 / 0.7 as far; gravity pulls a hanging arm back a little more the further it bends.
    aged = mjx_arm.load(domain=mjx_arm.Domain(name="soft", stiffness_scale=0.7))
    program = _held([1.0, 0.2, 0.2], 15.0)
    down = np.array([0.0, 0.0, -1.0])
    bend_source = np.arccos(source_arm.rollout(program, backend="c")[-1, 3:] @ down)
    bend_aged = np.arccos(aged.rollout(program, backend="c")[-1, 3:] @ down)
    assert bend_aged == pytest.approx(bend_source / 0.7, rel=0.08)


def test_absolute_viscosity_domain():
    arm = mjx_arm.load(domain=mjx_arm.Domain(viscosity=123.0, viscosity_scale=2.0))
    assert arm.mj_model.opt.viscosity == pytest.approx(246.0)


def test_foreign_mjcf_missing_tip_lists_the_name(tmp_path, small_xml):
    path = tmp_path / "no_tip.xml"
    path.write_text(small_xml.replace('name="tip"', 'name="end"'))
    with pytest.raises(mjx_arm.ModelValidationError, match=r"missing site 'tip'"):
        mjx_arm.load(path)
    no_chambers = small_xml.replace('name="chamber_1" tendon', 'name="valve_1" tendon')
    with pytest.raises(mjx_arm.ModelValidationError, match=r"chamber_1"):
        mjx_arm.load(xml=no_chambers)


def test_foreign_mjcf_with_the_names_loads(tmp_path, small_xml):
    path = tmp_path / "my_arm.xml"
    path.write_text(small_xml)
    arm = mjx_arm.load(path, domain=mjx_arm.Domain(viscosity=50.0))
    assert arm.path == path and arm.mj_model.opt.viscosity == pytest.approx(50.0)
    assert arm.rollout(_held([1.0, 0.2, 0.2], 0.3), backend="c").shape == (3, 6)


@pytest.mark.parametrize("backend", ["c", "mjx"])
def test_non_finite_pressures_name_where(small_xml, backend):
    arm = mjx_arm.load(xml=small_xml)
    programs = np.full((2, 4, 3), 1.0)
    programs[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match=r"trajectory 1, step 2, chamber 0"):
        arm.rollout(programs, backend=backend)
    with pytest.raises(ValueError, match=r"\[T, 3\] or \[B, T, 3\]"):
        arm.rollout(np.ones((4, 2)), backend=backend)


def test_out_of_range_pressures_saturate_like_a_valve(small_xml):
    arm = mjx_arm.load(xml=small_xml)
    wild = np.array([[10.0, -3.0, 0.1]] * 5)
    clipped = np.array([[3.5, 0.0, 0.2]] * 5)
    np.testing.assert_array_equal(arm.rollout(wild, backend="c"), arm.rollout(clipped, backend="c"))


@pytest.mark.slow
def test_twenty_segment_mjx_step_on_cpu_is_fast():
    """The CPU trap: without the XLA flag one 20-segment step takes minutes."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    params = dataclasses.replace(ArmParams(), n_segments=20)
    arm = mjx_arm.load(xml=generate_xml(params))
    model = arm.mjx_model
    data = mjx.make_data(model)
    data = data.replace(qpos=jnp.asarray(arm.rest_qpos, dtype=data.qpos.dtype))
    n_steps = 20
    steps = jax.jit(lambda d: jax.lax.fori_loop(0, n_steps, lambda _, x: mjx.step(model, x), d))
    steps = steps.lower(data).compile()
    start = time.perf_counter()
    jax.block_until_ready(steps(data))
    per_step = (time.perf_counter() - start) / n_steps
    print(f"\n20-segment MJX step on CPU: {per_step * 1e3:.1f} ms")
    assert per_step < 0.25


def test_mjcf_without_pose_sensors_gives_the_same_c_poses(small_xml):
    start, stop = small_xml.index("  <sensor>"), small_xml.index("</sensor>") + len("</sensor>\n")
    bare = mjx_arm.load(xml=small_xml[:start] + small_xml[stop:])
    assert bare.mj_model.nsensor == 0
    program = np.repeat(np.array([[3.0, 0.2, 1.0], [0.5, 2.5, 0.2]]), 5, axis=0)
    np.testing.assert_allclose(
        bare.rollout(program, backend="c"),
        mjx_arm.load(xml=small_xml).rollout(program, backend="c"),
        atol=1e-12,
    )


def test_c_rollouts_continue_from_their_end_states(small_xml):
    arm = mjx_arm.load(xml=small_xml, domain="constrained")
    program = np.random.default_rng(1).uniform(0.0, 3.5, size=(3, 12, 3))
    whole = arm.rollout(program, backend="c")
    start = arm.rest_state(3)
    assert start.physics.shape[0] == 3 and np.all(start.pressure_bar == arm.valve.p_min_bar)
    first, ok_first, middle = arm.rollout_c_from(start, program[:, :5])
    second, ok_second, end = arm.rollout_c_from(middle, program[:, 5:])
    # Chained calls are one rollout: bit for bit, and the chamber pressures carry over.
    np.testing.assert_array_equal(np.concatenate([first, second], 1), whole)
    assert ok_first.all() and ok_second.all()
    assert not np.allclose(middle.pressure_bar, start.pressure_bar)
    assert end.physics.shape == start.physics.shape
    with pytest.raises(ValueError, match=r"\[B, T, 3\]"):
        arm.rollout_c_from(start, program[0])
    with pytest.raises(ValueError, match="3 states"):
        arm.rollout_c_from(start, program[:2])


def test_c_rollouts_in_chunks_equal_one_call(small_xml, monkeypatch):
    """Chunked MuJoCo C rollouts bound memory (`Arm.rollout`'s chunk) and change no number."""
    from mujoco import rollout as mj_rollout

    arm = mjx_arm.load(xml=small_xml)
    programs = np.random.default_rng(2).uniform(0.0, 3.5, size=(5, 7, 3))
    whole = arm.rollout(programs, backend="c")
    qpos_whole, _ = arm.rollout_with_qpos(programs)
    batches = []
    call = mj_rollout.Rollout.rollout

    def counting(self, model, data, initial_state, *args, **kwargs):
        batches.append(len(initial_state))
        return call(self, model, data, initial_state, *args, **kwargs)

    monkeypatch.setattr(mj_rollout.Rollout, "rollout", counting)
    np.testing.assert_array_equal(arm.rollout(programs, backend="c", chunk=2), whole)
    assert batches == [2, 2, 1]
    qpos, poses = arm.rollout_with_qpos(programs, chunk=3)
    np.testing.assert_array_equal(qpos, qpos_whole)
    np.testing.assert_array_equal(poses, whole)
    poses, ok, end = arm.rollout_c_from(arm.rest_state(5), programs, chunk=2)
    np.testing.assert_array_equal(poses, whole)
    assert ok.all() and end.physics.shape[0] == 5 and not end.diverged.any()
    with pytest.raises(ValueError, match="chunk"):
        arm.rollout(programs, backend="c", chunk=0)


def _dot_precisions(jaxpr) -> list:
    """The `precision` of every dot_general in `jaxpr` and the jaxprs nested in it (scans,
    conditionals, jitted calls)."""
    from jax.extend import core as jax_core

    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name == "dot_general":
            found.append(eqn.params["precision"])
        for sub in jax_core.jaxprs_in_params(eqn.params):
            found += _dot_precisions(sub)
    return found


def test_mjx_physics_asks_for_full_float32_matrix_products(small_xml):
    """On NVIDIA GPUs JAX's default lets XLA compute float32 products in TensorFloat32, which
    made the MJX tracker 9.4x coarser than MuJoCo C on an H100; every product of a control
    period must ask for HIGHEST, whatever the caller's default is."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    arm = mjx_arm.load(xml=small_xml)
    period = arm.period_fn(arm.mjx_model)
    data = mjx.make_data(arm.mjx_model)
    carry = (data, jnp.zeros(3, jnp.float32), jnp.array(True))
    with jax.default_matmul_precision("bfloat16"):
        jaxpr = jax.make_jaxpr(period)(carry, jnp.ones(3, jnp.float32)).jaxpr
    precisions = _dot_precisions(jaxpr)
    highest = (jax.lax.Precision.HIGHEST, jax.lax.Precision.HIGHEST)
    assert precisions and all(p == highest for p in precisions), set(precisions)


def test_mjx_precision_is_one_setting_a_benchmark_can_lower(small_xml, monkeypatch):
    """`bench.teacher --matmul-precisions default` sets `MJX_MATMUL_PRECISION` to None: the
    period then traces with the caller's precision, as JAX's default would on a GPU."""
    import jax
    import jax.numpy as jnp
    from mujoco import mjx

    from mjx_arm import arm as arm_module

    monkeypatch.setattr(arm_module, "MJX_MATMUL_PRECISION", None)
    arm = mjx_arm.load(xml=small_xml)
    data = mjx.make_data(arm.mjx_model)
    carry = (data, jnp.zeros(3, jnp.float32), jnp.array(True))
    with jax.default_matmul_precision("bfloat16"):
        jaxpr = jax.make_jaxpr(arm.period_fn(arm.mjx_model))(carry, jnp.ones(3, jnp.float32))
    precisions = set(_dot_precisions(jaxpr.jaxpr))
    # Products are traced (an empty set would pass the next line), and with the caller's setting.
    assert precisions, "no matrix product traced"
    assert (jax.lax.Precision.HIGHEST, jax.lax.Precision.HIGHEST) not in precisions, precisions
    assert (jax.lax.Precision.DEFAULT, jax.lax.Precision.DEFAULT) in precisions, precisions
