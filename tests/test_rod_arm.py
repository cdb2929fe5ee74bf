"""The reference rod as an arm (`mjx_arm.load_rod`): `Arm.rollout`'s interface, the committed
rod path's numbers, the chain's valves and domains, and its refusals.

Every rollout here is 1 s (10 control periods), so each compiled shape costs a few seconds.
"""

import dataclasses
import json

import numpy as np
import pytest

import mjx_arm
from mjx_arm import cosserat, rod_arm, rod_check, valve
from mjx_arm.model_gen import ArmParams
from mjx_arm.programs import held_program

PERIODS = 10
LENGTH_M = ArmParams().length_m


@pytest.fixture(scope="module")
def programs() -> np.ndarray:
    """Two 1 s programs [2, 10, 3] (bar) of targets held 0.2-0.5 s."""
    return np.stack([held_program(seed, PERIODS / 10, (2, 5)) for seed in (0, 1)])


@pytest.fixture(scope="module")
def source_rod() -> rod_arm.RodArm:
    return mjx_arm.load_rod("source")


@pytest.mark.parametrize("domain", ["source", "constrained"])
def test_rod_arm_agrees_with_the_committed_rod_path(domain, programs):
    # The fidelity report's path: cosserat.rollout with CosseratParams.from_arm (float64).
    reference = cosserat.rollout(programs, cosserat.CosseratParams.from_arm(ArmParams(), domain))
    poses = mjx_arm.load_rod(domain).rollout(programs)
    tip = np.linalg.norm(poses[..., :3] - reference[..., :3], axis=-1).max()
    assert tip <= rod_arm.AGREEMENT_FRACTION_OF_L * LENGTH_M
    np.testing.assert_allclose(poses[..., 3:], reference[..., 3:], atol=1e-9)
    # The programs move the tip, so agreement is not two rods at rest.
    assert np.linalg.norm(poses[:, -1, :3] - poses[:, 0, :3], axis=-1).min() > 0.005


def test_shapes_match_arm_rollout_and_batching_changes_nothing(source_rod, programs):
    batched = source_rod.rollout(programs)
    single = source_rod.rollout(programs[1])
    assert batched.shape == (2, PERIODS, 6) and single.shape == (PERIODS, 6)
    assert batched.dtype == single.dtype == np.float64
    np.testing.assert_allclose(single, batched[1], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(batched[..., 3:], axis=-1), 1.0, atol=1e-9)


def test_commands_saturate_like_the_chain_valves(source_rod):
    # Above 3.5 bar acts as 3.5, below the 0.2 bar floor (negative included) as the floor.
    wild = np.tile([9.0, -1.0, 0.0], (PERIODS, 1))
    clipped = np.tile([3.5, 0.2, 0.2], (PERIODS, 1))
    poses = source_rod.rollout(np.stack([wild, clipped]))
    np.testing.assert_array_equal(poses[0], poses[1])
    assert source_rod.valve == valve.ValveParams()  # the chain's constants, 0.2 s / 0.56 s


def test_the_valve_lags_the_command(source_rod):
    # A chamber stepped to 3.5 bar rises with tau = 0.2 s: after 0.1 s it is far from the
    # pose the same pressure reaches when held, and still moving after 1 s.
    poses = source_rod.rollout(np.tile([3.5, 0.2, 0.2], (PERIODS, 1)))
    held = cosserat.static_pose([3.5, 0.2, 0.2], source_rod.params)
    rest = source_rod.rest_pose()
    swing = np.linalg.norm(held[:3] - rest[:3])
    assert np.linalg.norm(poses[0, :3] - rest[:3]) < 0.3 * swing
    assert np.linalg.norm(poses[-1, :3] - poses[-2, :3]) > 1e-4


def test_domains_map_onto_the_rod():
    source = rod_arm.rod_params("source")
    constrained = rod_arm.rod_params("constrained")
    aged = rod_arm.rod_params("aged")
    assert source == cosserat.CosseratParams.from_arm(ArmParams(), "source")
    assert constrained == cosserat.CosseratParams.from_arm(ArmParams(), "constrained")
    assert aged.damping_per_s == constrained.damping_per_s == 8000.0
    assert aged.youngs_modulus_pa == pytest.approx(0.7 * constrained.youngs_modulus_pa)
    assert aged.shear_modulus_pa == pytest.approx(0.7 * constrained.shear_modulus_pa)
    custom = rod_arm.rod_params(mjx_arm.Domain(viscosity_scale=3.0, mass_scale=1.1))
    assert custom.damping_per_s == pytest.approx(2400.0)
    assert custom.mass_kg == pytest.approx(1.1 * source.mass_kg)
    assert dataclasses.replace(custom, damping_per_s=800.0, mass_kg=source.mass_kg) == source


def test_the_aged_arm_bends_further_than_the_constrained_one(programs):
    # Same medium, 0.7 x the stiffness: gravity and the chambers move the softer rod further.
    aged = mjx_arm.load_rod("aged")
    constrained = mjx_arm.load_rod("constrained")
    assert aged.rest_pose()[2] < constrained.rest_pose()[2]  # sags lower at rest
    move = {
        name: np.linalg.norm(rod.rollout(programs)[:, -1, :3] - rod.rest_pose()[:3], axis=-1)
        for name, rod in (("aged", aged), ("constrained", constrained))
    }
    assert (move["aged"] > move["constrained"]).all()


def test_float32_follows_float64(programs):
    rod32 = mjx_arm.load_rod("source", dtype="float32")
    poses32 = rod32.rollout(programs)
    poses64 = mjx_arm.load_rod("source").rollout(programs)
    assert poses32.dtype == np.float64  # returned as float64, like Arm.rollout
    tip = np.linalg.norm(poses32[..., :3] - poses64[..., :3], axis=-1).max()
    assert 0.0 < tip < 1e-3 * LENGTH_M  # different arithmetic, same motion


@pytest.mark.parametrize(
    "bad, message",
    [
        (np.zeros((PERIODS, 2)), "must be"),
        (np.zeros((0, PERIODS, 3)), "must be"),
        (np.zeros((2, 3, PERIODS, 3)), "must be"),
        (np.full((PERIODS, 3), np.nan), "non-finite"),
        (np.ones((PERIODS, 3), dtype=bool), "boolean"),
    ],
)
def test_bad_programs_are_refused_before_simulating(source_rod, bad, message):
    with pytest.raises(ValueError, match=message):
        source_rod.rollout(bad)


def test_the_rod_names_one_arm_in_every_domain():
    hashes = {mjx_arm.load_rod(d).model_hash for d in ("source", "constrained", "aged")}
    assert len(hashes) == 1 and hashes.pop().startswith("rod-")
    softer = dataclasses.replace(ArmParams(), length_m=0.21)
    assert mjx_arm.load_rod("source", arm=softer).model_hash != mjx_arm.load_rod().model_hash


def test_unrolling_the_step_loop_changes_nothing(source_rod, programs):
    unrolled = dataclasses.replace(source_rod, unroll=5).rollout(programs)
    np.testing.assert_allclose(unrolled, source_rod.rollout(programs), rtol=0, atol=1e-12)


def test_unroll_bench_writes_its_table(tmp_path):
    from bench import rod_unroll

    argv = ["--out", str(tmp_path), "--batch", "1", "--unroll", "1", "2", "--seconds", "0.2"]
    rod_unroll.main(argv + ["--repeats", "1"])
    stored = json.loads((tmp_path / "rod_unroll.json").read_text())
    assert [(r["batch"], r["unroll"]) for r in stored["rows"]] == [(1, 1), (1, 2)]
    assert stored["rows"][1]["largest_tip_difference_of_L"] < 1e-12
    assert "| 1 | 2 | " in (tmp_path / "rod_unroll.md").read_text()


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="unroll"):
        dataclasses.replace(mjx_arm.load_rod("source"), unroll=0)
    with pytest.raises(ValueError, match="dtype"):
        mjx_arm.load_rod("source", dtype="float16")
    with pytest.raises(ValueError, match="unknown domain"):
        mjx_arm.load_rod("underwater")
    with pytest.raises(ValueError, match="viscosity"):
        mjx_arm.load_rod(mjx_arm.Domain(viscosity=1.0))


def test_throughput_bench_writes_its_table(tmp_path):
    from bench import rod_throughput

    argv = ["--out", str(tmp_path), "--no-chain", "--dtypes", "float64", "--batch", "1"]
    rod_throughput.main(argv + ["--seconds", "0.1", "--accuracy-seconds", "0", "--repeats", "2"])
    stored = json.loads((tmp_path / "rod_throughput.json").read_text())
    assert [(r["backend"], r["batch"]) for r in stored["rows"]] == [("rod float64", 1)]
    row = stored["rows"][0]
    assert row["sim_s_per_wall_s"] > 0 and row["finite"] and len(row["wall_s_each"]) == 2
    assert row["wall_s"] == min(row["wall_s_each"])
    assert stored["command"].startswith("python -m bench.rod_throughput --out")
    table = (tmp_path / "rod_throughput.md").read_text()
    assert "| 1 | " in table and "| - | - | - |" in table  # no float32, no chain


@pytest.mark.parametrize("difference, status", [(0.0, 0), (2e-6, 1)])
def test_the_agreement_command_fails_above_1e_6_of_l(monkeypatch, capsys, difference, status):
    row = {"programs": 3, "seconds": 60.0, "max_d3_difference": 0.0}
    found = {"source": row | {"max_tip_fraction_of_L": 0.0}}
    found["constrained"] = row | {"max_tip_fraction_of_L": difference}
    monkeypatch.setattr(rod_check, "agreement", lambda seconds: found)
    assert rod_check.main([]) == status
    assert ("DOES NOT agree" in capsys.readouterr().out) == bool(status)


def test_a_diverged_trajectory_is_reported(monkeypatch, source_rod, programs):
    def diverging(params, dtype, valve_params, unroll):
        def run(commands):
            poses = np.zeros(commands.shape[:2] + (6,))
            poses[1, 3:] = np.nan  # trajectory 1 from period 3 on
            return poses

        return run

    monkeypatch.setattr(rod_arm, "_batched_rollout", diverging)
    with pytest.raises(mjx_arm.SimulationDivergedError, match="1 of 2.*trajectory 1 at period 3"):
        source_rod.rollout(programs)
